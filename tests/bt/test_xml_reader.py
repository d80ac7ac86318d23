"""The BehaviorTree.CPP v4 XML reader: syntax, SubTree scoping, monitors, and every error path with its position."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import behaviortreepy as btpy
import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.nodes import Fallback, Repeat, Sequence, SubTree
from bt_meta.bt.nodes.ticking import tick_once
from bt_meta.bt.registry import NodeInstance, NodeType, PortSpec, default_registry
from bt_meta.bt.xml.document import parse_text
from bt_meta.bt.xml.reader import load_tree_file, load_tree_text, resolve_document
from bt_meta.cli import main
from bt_meta.errors import TreeXMLError

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "hand_written_tree.xml"


pytestmark = pytest.mark.usefixtures("clean_blackboard")


class Recorder(py_trees.behaviour.Behaviour):
    """A custom leaf that records the values its ports had when it ran (read from the blackboard)."""

    def __init__(self, name: str, ports: dict[str, str], log: list, status: Status = Status.SUCCESS) -> None:
        super().__init__(name)
        self.ports = ports
        self.log = log
        self.result = status

    def update(self) -> Status:
        values = {}
        for port, value in self.ports.items():
            if value.startswith("{"):
                values[port] = py_trees.blackboard.Blackboard.get("/" + value[1:-1].lstrip("/"))
            else:
                values[port] = value
        self.log.append((self.name, values))
        return self.result


def custom_registry(log: list, results: dict[str, Status] | None = None):
    registry = default_registry()
    results = results or {}

    def make(node_id: str, category: str, ports: list[PortSpec]) -> NodeType:
        def factory(*, name: str, ports: dict[str, str], children: list) -> py_trees.behaviour.Behaviour:
            return Recorder(name, ports, log, results.get(node_id, Status.SUCCESS))

        return NodeType(node_id, category, ports, factory)  # type: ignore[arg-type]

    registry.register(make("MoveTo", "Action", [PortSpec("goal"), PortSpec("speed", "input", "double", "1.0")]))
    registry.register(make("Grasp", "Action", [PortSpec("object"), PortSpec("force", "input", "double", "10")]))
    registry.register(make("Release", "Action", []))
    registry.register(make("IsHolding", "Condition", [PortSpec("object")]))
    registry.register(make("Write", "Action", [PortSpec("out", "output")]))
    return registry


def xml(body: str, *extra_trees: str, main: str | None = "Main") -> str:
    attr = f' main_tree_to_execute="{main}"' if main else ""
    trees = "".join(extra_trees)
    return f'<root BTCPP_format="4"{attr}>\n<BehaviorTree ID="Main">\n{body}\n</BehaviorTree>{trees}</root>'


def error_of(text: str, registry=None, **kwargs) -> TreeXMLError:
    with pytest.raises(TreeXMLError) as info:
        load_tree_text(text, registry or default_registry(), path="tree.xml", **kwargs)
    return info.value


# ----------------------------------------------------------------------------------------------------- syntax


def test_compact_and_explicit_syntax_build_the_same_nodes():
    log: list = []
    registry = custom_registry(log)
    compact = load_tree_text(xml('<Sequence><MoveTo goal="a"/><IsHolding object="x"/></Sequence>'), registry)
    explicit = load_tree_text(
        xml('<Control ID="Sequence"><Action ID="MoveTo" goal="a"/><Condition ID="IsHolding" object="x"/></Control>'),
        registry,
    )
    for root in (compact, explicit):
        assert isinstance(root, Sequence)
        assert [c.bt_node.id for c in root.children] == ["MoveTo", "IsHolding"]
        assert [c.bt_node.category for c in root.children] == ["Action", "Condition"]
        assert root.children[0].bt_node.ports == {"goal": "a"}
    tick_once(explicit)
    assert log == [("MoveTo", {"goal": "a", "speed": "1.0"}), ("IsHolding", {"object": "x"})]


def test_explicit_decorator_and_names():
    root = load_tree_text(xml('<Decorator ID="Repeat" name="thrice" num_cycles="3"><AlwaysSuccess/></Decorator>'))
    assert isinstance(root, Repeat)
    assert root.name == "thrice"
    assert root.bt_node == NodeInstance("Repeat", "Decorator", {"num_cycles": "3"}, True, 3, "<string>")


def test_every_node_keeps_its_line_number():
    root = load_tree_text(xml("<Sequence>\n  <AlwaysSuccess/>\n\n  <AlwaysFailure/>\n</Sequence>"))
    assert root.bt_node.line == 3
    assert [c.bt_node.line for c in root.children] == [4, 6]


def test_tree_selection_main_explicit_and_single():
    two = xml("<AlwaysSuccess/>", '<BehaviorTree ID="Other"><AlwaysFailure/></BehaviorTree>')
    assert load_tree_text(two).bt_tree_id == "Main"
    root = load_tree_text(two, tree_id="Other")
    assert root.bt_tree_id == "Other"
    assert tick_once(root) == Status.FAILURE
    single = xml("<AlwaysSuccess/>", main=None)
    assert load_tree_text(single).bt_tree_id == "Main"


def test_the_hand_written_example_loads_and_runs_with_scoped_blackboards():
    log: list = []
    registry = custom_registry(log, {"IsHolding": Status.FAILURE})
    root = load_tree_file(EXAMPLE, registry)
    assert root.bt_tree_id == "PickAndPlace"
    for _ in range(10):
        if tick_once(root) != Status.RUNNING:
            break
    assert root.status == Status.SUCCESS
    assert log == [
        ("IsHolding", {"object": "cube"}),  # literal remapping initialises the subtree's private entry
        ("approach", {"goal": "table/left", "speed": "0.5"}),  # target -> parent's pick_pose
        ("Grasp", {"object": "cube", "force": "20"}),
        ("move above bin", {"goal": "bin/center", "speed": "1.0"}),  # _autoremap
        ("Release", {}),
        ("retreat", {"goal": "home", "speed": "1.0"}),
    ]
    subtrees = [node for node in root.iterate() if isinstance(node, SubTree)]
    assert [s.bt_node.id for s in subtrees] == ["Pick", "Place"]
    assert subtrees[0].bt_node.ports == {"target": "{pick_pose}", "object": "cube"}
    assert subtrees[1].bt_node.ports == {"_autoremap": "true"}


def test_the_hand_written_example_loads_in_behaviortree_cpp():
    tree = ET.fromstring(EXAMPLE.read_text())
    custom = {"MoveTo", "Grasp", "Release", "IsHolding"}
    for element in tree.iter():
        if element.tag in custom:  # behaviortreepy cannot declare ports for nodes registered from Python
            for attr in [a for a in element.attrib if a != "name" and not a.startswith("_")]:
                del element.attrib[attr]
    factory = btpy.BehaviorTreeFactory()
    calls: list[str] = []
    for node_id in ("MoveTo", "Grasp", "Release"):
        factory.register_simple_action(node_id, lambda _n, i=node_id: calls.append(i) or btpy.NodeStatus.SUCCESS)
    factory.register_simple_condition("IsHolding", lambda _n: calls.append("IsHolding") or btpy.NodeStatus.FAILURE)
    bt = factory.create_tree_from_text(ET.tostring(tree, encoding="unicode"))
    assert bt.tick_while_running(0) == btpy.NodeStatus.SUCCESS
    assert calls == ["IsHolding", "MoveTo", "Grasp", "MoveTo", "Release", "MoveTo"]
    assert bt.root_blackboard().get_string("place_pose") == "bin/center"


def test_subtree_keys_are_private_unless_remapped():
    log: list = []
    registry = custom_registry(log)
    text = xml(
        '<Sequence><SetBlackboard output_key="goal" value="outer"/><SubTree ID="S" dest="{goal}"/>'
        '<MoveTo name="after" goal="{goal}"/></Sequence>',
        '<BehaviorTree ID="S"><Sequence><SetBlackboard output_key="goal" value="inner"/>'
        '<MoveTo name="inside" goal="{goal}"/><MoveTo name="dest" goal="{dest}"/>'
        '<MoveTo name="root" goal="{@goal}"/></Sequence></BehaviorTree>',
    )
    root = load_tree_text(text, registry)
    assert tick_once(root) == Status.SUCCESS
    assert [(name, values["goal"]) for name, values in log] == [
        ("inside", "inner"),
        ("dest", "outer"),
        ("root", "outer"),
        ("after", "outer"),
    ]
    assert py_trees.blackboard.Blackboard.get("/goal") == "outer"


def test_subtree_writes_through_a_remapped_port_and_same_name_shorthand():
    text = xml(
        '<Sequence><SubTree ID="S" result="{answer}" flag="{=}"/></Sequence>',
        '<BehaviorTree ID="S"><Sequence><SetBlackboard output_key="result" value="42"/>'
        '<SetBlackboard output_key="flag" value="up"/></Sequence></BehaviorTree>',
    )
    assert tick_once(load_tree_text(text)) == Status.SUCCESS
    assert py_trees.blackboard.Blackboard.get("/answer") == "42"
    assert py_trees.blackboard.Blackboard.get("/flag") == "up"


def test_builtin_ports_read_from_the_blackboard():
    text = xml('<Sequence><SetBlackboard output_key="n" value="2"/><Repeat num_cycles="{n}"><L/></Repeat></Sequence>')
    count = []
    registry = default_registry()
    registry.register(NodeType("L", "Action", [], lambda **_: py_trees.behaviours.Success(name="L")), replace=False)
    root = load_tree_text(text, registry, wake_up=False)
    for node in root.iterate():
        if node.name == "L":
            node.update = lambda: count.append(1) or Status.SUCCESS  # type: ignore[method-assign]
    assert tick_once(root) == Status.SUCCESS
    assert len(count) == 2


# ----------------------------------------------------------------------------------------------------- monitors


def test_wrap_action_wraps_custom_actions_unless_opted_out():
    log: list = []
    registry = custom_registry(log)
    wrapped: list[NodeInstance] = []

    def wrap(behaviour, instance):
        wrapped.append(instance)
        monitor = py_trees.decorators.PassThrough(name=f"monitor {behaviour.name}", child=behaviour)
        monitor.is_monitor = True
        return monitor

    text = xml(
        '<Sequence><MoveTo goal="a"/><MoveTo name="quiet" goal="b" _monitor="false"/>'
        '<IsHolding object="x"/><AlwaysSuccess/></Sequence>'
    )
    root = load_tree_text(text, registry, wrap_action=wrap)
    assert [i.id for i in wrapped] == ["MoveTo"]
    assert wrapped[0].ports == {"goal": "a"}
    assert root.children[0].name == "monitor MoveTo"
    assert root.children[1].bt_node.monitor is False
    assert tick_once(root) == Status.SUCCESS


# ----------------------------------------------------------------------------------------------------- errors


def test_malformed_xml_names_the_position():
    error = error_of('<root BTCPP_format="4">\n<BehaviorTree ID="Main">\n  <Sequence>\n</BehaviorTree></root>')
    assert error.line == 4
    assert error.message.startswith("malformed XML: mismatched tag")
    assert str(error).startswith("tree.xml:4:")


def test_unknown_node_lists_close_matches():
    error = error_of(xml("<Sequence>\n  <AlwaysSucess/>\n</Sequence>"))
    assert (error.line, error.column) == (4, 3)
    assert error.message == "unknown node ID 'AlwaysSucess'; did you mean AlwaysSuccess, AlwaysFailure?"


def test_unknown_node_without_close_match_lists_known_ids():
    error = error_of(xml("<Zzz/>"))
    assert error.message.startswith("unknown node ID 'Zzz'; known IDs: AlwaysFailure, AlwaysSuccess, AsyncFallback")


def test_missing_required_port():
    error = error_of(xml("<Repeat>\n<AlwaysSuccess/></Repeat>"))
    assert error.line == 3
    assert error.message == "node 'Repeat' is missing required port 'num_cycles'"


def test_missing_required_port_of_a_custom_node():
    error = error_of(xml("<MoveTo speed='2'/>"), custom_registry([]))
    assert error.message == "node 'MoveTo' is missing required port 'goal'"


def test_bad_attribute_value():
    error = error_of(
        xml('<Sequence>\n <RetryUntilSuccessful num_attempts="abc"><AlwaysSuccess/></RetryUntilSuccessful></Sequence>')
    )
    assert (error.line, error.column) == (4, 2)
    assert error.message == "node 'RetryUntilSuccessful': port 'num_attempts' expects int, got 'abc'"
    error = error_of(xml('<MoveTo goal="a" speed="fast"/>'), custom_registry([]))
    assert error.message == "node 'MoveTo': port 'speed' expects double, got 'fast'"
    error = error_of(xml('<Timeout msec="-5"><AlwaysSuccess/></Timeout>'))
    assert error.message == "node 'Timeout': port 'msec' expects unsigned int, got '-5'"


def test_undeclared_port():
    error = error_of(xml('<Repeat cycles="3"><AlwaysSuccess/></Repeat>'))
    assert error.message == "node 'Repeat' has no port 'cycles' (ports: num_cycles)"


def test_subtree_that_does_not_exist():
    error = error_of(xml('<Sequence>\n  <SubTree ID="Missing"/>\n</Sequence>'))
    assert (error.line, error.column) == (4, 3)
    assert error.message == (
        "SubTree 'Missing' does not exist; trees in this file: Main (a tree in another file needs "
        '<include path="..."/> or the file on the command line)'
    )


def test_recursive_subtrees():
    text = xml(
        '<SubTree ID="A"/>',
        '\n<BehaviorTree ID="A"><Sequence><SubTree ID="B"/></Sequence></BehaviorTree>',
        '\n<BehaviorTree ID="B">\n<SubTree ID="A"/></BehaviorTree>',
    )
    error = error_of(text)
    assert error.message == "recursive SubTree: A -> B -> A"
    assert error.line == 7


@pytest.mark.parametrize(
    "text",
    [
        '<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;">]>\n'
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence name="&lol2;"><AlwaysSuccess/></Sequence>'
        "</BehaviorTree></root>",
        '<?xml version="1.0"?>\n<!DOCTYPE root SYSTEM "http://example.com/evil.dtd">\n<root/>',
    ],
)
def test_doctype_and_entities_are_refused(text):
    error = error_of(text)
    assert error.line == 2
    assert error.message == "DOCTYPE declarations are not allowed in tree XML (no DTDs, no entities)"


def test_undeclared_entity_reference_is_malformed():
    error = error_of(xml('<Sequence name="&xxe;"><AlwaysSuccess/></Sequence>'))
    assert error.message == "malformed XML: undefined entity"
    assert error.line == 3


def test_decorator_needs_exactly_one_child():
    error = error_of(xml("<Inverter>\n<AlwaysSuccess/><AlwaysFailure/></Inverter>"))
    assert error.message == "Decorator 'Inverter' needs exactly 1 child, got 2"
    assert error.line == 3
    error = error_of(xml("<ForceSuccess/>"))
    assert error.message == "Decorator 'ForceSuccess' needs exactly 1 child, got 0"
    error = error_of(xml("<Sequence/>"))
    assert error.message == "Control 'Sequence' needs at least 1 child, got 0"
    error = error_of(xml("<AlwaysSuccess><AlwaysSuccess/></AlwaysSuccess>"))
    assert error.message == "Action 'AlwaysSuccess' needs exactly 0 children, got 1"


def test_explicit_category_must_match():
    error = error_of(xml('<Condition ID="Sequence"><AlwaysSuccess/></Condition>'))
    assert error.message == "node 'Sequence' is a Control, not a Condition"
    error = error_of(xml("<Action/>"))
    assert error.message == "<Action> needs an ID attribute naming the node"


def test_document_level_errors():
    assert error_of('<root BTCPP_format="3"><BehaviorTree ID="M"><AlwaysSuccess/></BehaviorTree></root>').message == (
        'BTCPP_format="3" is not supported; bt-meta reads BehaviorTree.CPP v4 XML (BTCPP_format="4")'
    )
    assert error_of("<tree/>").message == "the top element must be <root>, got <tree>"
    assert error_of('<root BTCPP_format="4"/>').message == "no <BehaviorTree> in the document"
    two = xml("<AlwaysSuccess/>", '<BehaviorTree ID="B"><AlwaysSuccess/></BehaviorTree>', main=None)
    assert error_of(two).message == "several trees (Main, B) and no main_tree_to_execute; choose one by ID"
    assert error_of(two, tree_id="C").message == "no <BehaviorTree ID='C'>; trees: Main, B"
    bad_main = xml("<AlwaysSuccess/>", main="Nope")
    assert error_of(bad_main).message == "main_tree_to_execute='Nope' names no <BehaviorTree>; trees: Main"
    empty = '<root BTCPP_format="4"><BehaviorTree ID="M"><A/><B/></BehaviorTree></root>'
    assert error_of(empty).message == "<BehaviorTree ID='M'> must have exactly one child node, got 2"


def test_script_syntax_errors_are_located_at_load():
    error = error_of(xml('<AlwaysSuccess _skipIf="x == "/>'))
    assert error.message == "_skipIf: expected operand at the end of the script (at character 6 of 'x == ')"
    assert (error.line, error.column) == (3, 1)
    error = error_of(xml('<Script code="a := 1 + 2 &amp; 3"/>'))
    assert error.message.startswith("Script code: operator cannot be mixed with previous operators")
    assert error_of(xml('<ScriptCondition code="x := 1;"/>')).message.startswith(
        "ScriptCondition code: unexpected trailing ';'"
    )


def test_editor_metadata_attributes_are_ignored_like_behaviortree_cpp():
    root = load_tree_text(xml('<AlwaysSuccess _collapsed="true" _uid="7" _fullpath="x" _description="d"/>'))
    assert root.bt_node.ports == {}


def test_bad_attributes_say_so():
    assert error_of(xml('<AlwaysSuccess _monitor="maybe"/>')).message == '_monitor="maybe" must be "true" or "false"'
    assert error_of(xml('<AlwaysSuccess _autoremap="true"/>')).message == "_autoremap is only valid on <SubTree>"
    v3 = xml('<SubTree ID="S" __shared_blackboard="true"/>', '<BehaviorTree ID="S"><AlwaysSuccess/></BehaviorTree>')
    assert error_of(v3).message == (
        '__shared_blackboard is BehaviorTree.CPP v3 syntax; in v4 use _autoremap="true" or remap ports'
    )


def test_parallel_thresholds_are_checked_when_literal():
    error = error_of(xml('<Parallel success_count="3"><AlwaysSuccess/><AlwaysSuccess/></Parallel>'))
    assert error.message == "Parallel success_count=3 needs 3 children, it has 2"
    error = error_of(xml('<Parallel failure_count="3"><AlwaysSuccess/><AlwaysSuccess/></Parallel>'))
    assert error.message == "Parallel failure_count=3 needs 3 children, it has 2"
    assert load_tree_text(xml('<Parallel success_count="-3"><AlwaysSuccess/><AlwaysSuccess/></Parallel>'))


def test_missing_file():
    with pytest.raises(TreeXMLError) as info:
        load_tree_file("/nonexistent/tree.xml")
    assert info.value.message == "no such tree XML file"


# ----------------------------------------------------------------------------------------------------- TreeNodesModel

MODEL_ONLY = """<root BTCPP_format="4">
<BehaviorTree ID="Main"><Fallback><Detect region="table"/><Detect/></Fallback></BehaviorTree>
<TreeNodesModel>
  <Condition ID="Detect"><input_port name="region" type="std::string"/></Condition>
</TreeNodesModel>
</root>"""


def test_model_declared_nodes_are_validated_but_not_instantiated():
    document = parse_text(MODEL_ONLY, "m.xml")
    assert document.models["Detect"].ports == [PortSpec("region")]
    # BT.CPP: a model port without a default is not required at load (only a node that reads it complains).
    assert [c.ports for c in resolve_document(document).children] == [{"region": "table"}, {}]
    fixed = parse_text(MODEL_ONLY.replace("<Detect/>", '<Detect region="bin"/>'), "m.xml")
    resolved = resolve_document(fixed)
    assert [c.ports for c in resolved.children] == [{"region": "table"}, {"region": "bin"}]
    with pytest.raises(TreeXMLError) as info:
        load_tree_text(MODEL_ONLY.replace("<Detect/>", '<Detect region="bin"/>'))
    assert info.value.message == (
        "node 'Detect' is declared in <TreeNodesModel> (line 4) but not registered; load the plugin that implements it"
    )


def test_registered_nodes_ignore_the_model():
    text = MODEL_ONLY.replace("Detect", "IsHolding").replace("region", "object")
    root = load_tree_text(text.replace("<IsHolding/>", '<IsHolding object="b"/>'), custom_registry([]))
    assert isinstance(root, Fallback)


def test_bad_model_entries():
    bad = MODEL_ONLY.replace("input_port", "sideways_port")
    assert error_of(bad).message == (
        "<sideways_port> in the model of 'Detect': expected input_port, output_port or inout_port"
    )


# ----------------------------------------------------------------------------------------------------- CLI


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bt_meta.cli", *args], capture_output=True, text=True, check=False)


def test_show_prints_a_unicode_tree(capsys):
    assert main(["show", str(EXAMPLE)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"PickAndPlace ({EXAMPLE})"
    assert lines[1] == 'Sequence "pick and place"'
    assert '├── SubTree Pick "pick the cube" target="{pick_pose}" object="cube"' in lines
    assert '│           │   └── MoveTo "approach" goal="{target}" speed="0.5"' in lines
    assert "│       └── Release [no monitor]" in lines
    assert lines[-1] == '    └── MoveTo "retreat" goal="home" speed="1.0"'


def test_show_selects_a_tree(capsys):
    assert main(["show", str(EXAMPLE), "--tree", "Place"]) == 0
    assert capsys.readouterr().out.splitlines()[1:] == [
        'Sequence "move and release"',
        '├── MoveTo "move above bin" goal="{place_pose}"',
        "└── Release [no monitor]",
    ]


def test_show_bad_xml_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Sequense/>\n</BehaviorTree></root>')
    result = run_cli("show", str(bad))
    assert result.returncode == 2
    hint = "did you mean Sequence, AsyncSequence?"
    assert result.stderr == f"{bad}:3:1: unknown node ID 'Sequense'; {hint}\n"
    assert result.stdout == ""


def test_two_loaded_trees_do_not_share_subtree_scopes():
    text = xml(
        '<Sequence><SubTree ID="S" n="{@start}"/><SetBlackboard output_key="seen" value="{@out}"/></Sequence>',
        '<BehaviorTree ID="S"><Sequence><SetBlackboard output_key="own" value="{n}"/>'
        '<SetBlackboard output_key="@out" value="{own}"/></Sequence></BehaviorTree>',
    )
    first, second = load_tree_text(text), load_tree_text(text)
    py_trees.blackboard.Blackboard.set("/start", "one")
    assert tick_once(first) == Status.SUCCESS
    py_trees.blackboard.Blackboard.set("/start", "two")
    assert tick_once(second) == Status.SUCCESS
    private = sorted(k for k in py_trees.blackboard.Blackboard.storage if k.endswith("/own"))
    assert len(private) == 2
    assert sorted(py_trees.blackboard.Blackboard.get(k) for k in private) == ["one", "two"]
    assert py_trees.blackboard.Blackboard.get("/seen") == "two"
