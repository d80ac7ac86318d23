"""Trees spread over several files (``<include>``, ``--subtrees``, ``--include-path``), ``--tree``, stubs for nodes
nobody implements, and ``show --plugins``; the include layout is checked against BehaviorTree.CPP itself."""

from __future__ import annotations

from pathlib import Path

import behaviortreepy as btpy
import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.nodes.ticking import tick_exactly_once
from bt_meta.bt.registry import NodeType, default_registry
from bt_meta.bt.xml.document import TreeSources, parse_file
from bt_meta.bt.xml.reader import load_tree_file
from bt_meta.cli import main
from bt_meta.errors import TreeXMLError

pytestmark = pytest.mark.usefixtures("clean_blackboard")

MAIN = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <include path="sub/approach.xml"/>
  <BehaviorTree ID="Main">
    <Sequence>
      <Script code="tries := 0"/>
      <SubTree ID="Approach" _autoremap="true"/>
      <Detect _collapsed="false"/>
    </Sequence>
  </BehaviorTree>
  <TreeNodesModel>
    <Condition ID="Detect"><input_port name="target"/></Condition>
  </TreeNodesModel>
</root>
"""
APPROACH = """<root BTCPP_format="4">
  <include path="../common/retry.xml"/>
  <BehaviorTree ID="Approach">
    <RetryUntilSuccessful num_attempts="3">
      <Sequence>
        <Script code="tries += 1"/>
        <SubTree ID="Move" _autoremap="true"/>
      </Sequence>
    </RetryUntilSuccessful>
  </BehaviorTree>
</root>
"""
RETRY = """<root BTCPP_format="4">
  <BehaviorTree ID="Move"><MoveBase name="go" _onFailure="failed := true"/></BehaviorTree>
</root>
"""


@pytest.fixture
def project(tmp_path: Path) -> Path:
    (tmp_path / "sub").mkdir()
    (tmp_path / "common").mkdir()
    (tmp_path / "main.xml").write_text(MAIN)
    (tmp_path / "sub" / "approach.xml").write_text(APPROACH)
    (tmp_path / "common" / "retry.xml").write_text(RETRY)
    return tmp_path


def test_includes_are_relative_to_the_including_file(project: Path) -> None:
    document = parse_file(project / "main.xml")
    assert sorted(document.trees) == ["Approach", "Main", "Move"]
    assert document.trees["Move"].path == str(project / "sub" / "../common/retry.xml")
    assert len(document.files) == 3


def test_an_included_tree_ticks_like_behaviortree_cpp(project: Path) -> None:
    scripts = {"MoveBase": ["FAILURE", "RUNNING", "SUCCESS"], "Detect": ["SUCCESS"]}
    factory = btpy.BehaviorTreeFactory()
    log: list[tuple[str, str]] = []
    for name, script in scripts.items():
        calls = [0]

        def step(_node: object, name: str = name, script: list[str] = script, calls: list[int] = calls) -> object:
            status = script[calls[0] % len(script)]
            calls[0] += 1
            log.append((name, status))
            return getattr(btpy.NodeStatus, status)

        factory.register_simple_stateful_action(name, step, step)
    theirs = factory.create_tree_from_file(str(project / "main.xml"))
    expected = []
    for _ in range(6):
        status = theirs.tick_exactly_once().name
        expected.append((status, list(log)))
        log.clear()

    ours_log: list[tuple[str, str]] = []
    registry = default_registry()
    for name, script in scripts.items():

        class Scripted(py_trees.behaviour.Behaviour):
            def __init__(self, label: str, script: list[str] = script, node_id: str = name) -> None:
                super().__init__(label)
                self.script, self.calls, self.node_id = script, 0, node_id

            def update(self) -> Status:
                status = self.script[self.calls % len(self.script)]
                self.calls += 1
                ours_log.append((self.node_id, status))
                return Status[status]

        registry.register(NodeType(name, "Action", [], lambda name, ports, children, cls=Scripted: cls(name)),
                          replace=True)
    ours = load_tree_file(project / "main.xml", registry)
    actual = []
    for _ in range(6):
        actual.append((tick_exactly_once(ours).name, list(ours_log)))
        ours_log.clear()
    assert actual == expected
    assert theirs.root_blackboard().get_string("tries") == str(py_trees.blackboard.Blackboard.storage["/tries"])


def test_include_errors_are_located(project: Path) -> None:
    (project / "common" / "retry.xml").write_text('<root BTCPP_format="4"><include path="../main.xml"/></root>')
    with pytest.raises(TreeXMLError) as info:
        parse_file(project / "main.xml")
    assert "<include> cycle: " in info.value.message and info.value.path.endswith("retry.xml")
    (project / "common" / "retry.xml").unlink()
    with pytest.raises(TreeXMLError) as info:
        parse_file(project / "main.xml")
    assert info.value.message.startswith("<include path='../common/retry.xml'>: no such file")
    assert (info.value.path, info.value.line) == (str(project / "sub" / "approach.xml"), 2)


def test_the_include_path_and_extra_files_supply_trees(project: Path, tmp_path_factory: pytest.TempPathFactory) -> None:
    elsewhere = tmp_path_factory.mktemp("lib")
    (project / "common" / "retry.xml").rename(elsewhere / "retry.xml")
    (project / "sub" / "approach.xml").write_text(APPROACH.replace("../common/retry.xml", "retry.xml"))
    document = parse_file(project / "main.xml", TreeSources(include_path=(elsewhere,)))
    assert "Move" in document.trees
    # A main file without the include, with the subtree files given by folder.
    (project / "main.xml").write_text(MAIN.replace('  <include path="sub/approach.xml"/>\n', ""))
    with pytest.raises(TreeXMLError) as info:
        parse_file(project / "main.xml").trees and load_tree_file(project / "main.xml")
    assert "SubTree 'Approach' does not exist" in info.value.message
    document = parse_file(project / "main.xml", TreeSources((elsewhere,), (project / "sub",)))
    assert sorted(document.trees) == ["Approach", "Main", "Move"]


def test_a_tree_defined_twice_across_files_names_both(project: Path) -> None:
    (project / "common" / "retry.xml").write_text(RETRY.replace('ID="Move"', 'ID="Main"'))
    with pytest.raises(TreeXMLError) as info:
        parse_file(project / "main.xml")
    assert info.value.message == f"a <BehaviorTree ID='Main'> is already defined in {project / 'main.xml'}:3"


def test_show_and_tick_take_tree_and_stub_options(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main_xml = str(project / "main.xml")
    assert main(["show", main_xml, "--tree", "Move", "--stub-unknown"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines() == [f"Move ({main_xml})", 'MoveBase "go" _onFailure="failed := true"']
    assert main(["show", main_xml]) == 2
    assert "unknown node ID 'MoveBase'" in capsys.readouterr().err
    code = main(["tick", main_xml, "--stub-unknown", "--stub", "MoveBase=FAILURE,RUNNING,SUCCESS", "--ticks", "5"])
    captured = capsys.readouterr()
    out = captured.out
    assert code == 0, captured.err
    # tick 1: FAILURE, the retry wakes the tree, RUNNING; tick 2: SUCCESS
    assert out.splitlines()[-1].startswith("SUCCESS after 2 ticks")
    assert main(["tick", main_xml, "--stub-unknown", "--stub", "MoveBase=FAILURE", "--ticks", "9"]) == 1
    capsys.readouterr()
    assert main(["tick", main_xml, "--stub", "MoveBase=maybe"]) == 2
    assert "--stub needs --stub-unknown" in capsys.readouterr().err
    assert main(["tick", main_xml, "--stub-unknown", "--stub", "MoveBase=maybe"]) == 2
    assert "'MAYBE' is not SUCCESS, FAILURE or RUNNING" in capsys.readouterr().err


def test_show_loads_plugins_that_register_nodes(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plugins = project / "myplugins"
    plugins.mkdir()
    (plugins / "nav_nodes.py").write_text(
        "import py_trees\n"
        "from bt_meta.hookspecs import hookimpl\n"
        "from bt_meta.bt.registry import NodeType, PortSpec\n"
        "@hookimpl\n"
        "def bt_meta_register_nodes(registry, domain):\n"
        "    registry.register(NodeType('MoveBase', 'Action', [PortSpec('goal', default='home')],\n"
        "                      lambda name, ports, children: py_trees.behaviours.Success(name)))\n"
    )
    assert main(["show", str(project / "main.xml"), "--plugins", str(plugins)]) == 0
    assert 'MoveBase "go"' in capsys.readouterr().out


SUBTREE_MODEL = """<root BTCPP_format="4" main_tree_to_execute="M">
<BehaviorTree ID="M"><Sequence><Script code="out := ''"/><SubTree ID="S"/><SubTree ID="S" n="3"/></Sequence>
</BehaviorTree>
<BehaviorTree ID="S"><Script code="@out := @out .. n"/></BehaviorTree>
<TreeNodesModel><SubTree ID="S"><input_port name="n" default="7"/></SubTree></TreeNodesModel>
</root>"""


def test_subtree_model_defaults_fill_missing_ports_like_behaviortree_cpp() -> None:
    from bt_meta.bt.nodes.ticking import tick_once
    from bt_meta.bt.xml.reader import load_tree_text

    theirs = btpy.BehaviorTreeFactory().create_tree_from_text(SUBTREE_MODEL)
    assert theirs.tick_once().name == "SUCCESS"
    assert tick_once(load_tree_text(SUBTREE_MODEL)) == Status.SUCCESS
    assert py_trees.blackboard.Blackboard.storage["/out"] == theirs.root_blackboard().get_string("out") == "73"


def test_tree_options_refuse_a_task_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tick", "trees/letters.yaml", "--problem", "A", "--tree", "X"]) == 2
    assert "--tree, --include-path, --subtrees and --stub-unknown apply to tree XML" in capsys.readouterr().err


def test_show_warns_about_xml_that_only_behaviortree_cpp_accepts(tmp_path: Path) -> None:
    import subprocess
    import sys

    tree = tmp_path / "lenient.xml"
    body = '<ScriptCondition code="1 && 1"/>'
    tree.write_text(f'<root BTCPP_format="4"><BehaviorTree ID="M">{body}</BehaviorTree></root>')
    result = subprocess.run([sys.executable, "-m", "bt_meta.cli", "show", str(tree)], capture_output=True, text=True)
    assert result.returncode == 0
    assert result.stdout.splitlines() == [f"M ({tree})", 'ScriptCondition code="1 && 1"']
    assert result.stderr.splitlines() == [
        f"{tree}:1:70: warning: unescaped '&' in an attribute value (BehaviorTree.CPP accepts it; write &amp; to make "
        "the XML well formed)",
        f"{tree}:1:71: warning: unescaped '&' in an attribute value (BehaviorTree.CPP accepts it; write &amp; to make "
        "the XML well formed)",
    ]
