"""Python functions and classes registered as nodes by a decorator (no pluggy hook)."""

from __future__ import annotations

from pathlib import Path

import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.domain_nodes import domain_registry
from bt_meta.bt.nodes.ticking import tick_once
from bt_meta.bt.python_nodes import action, condition
from bt_meta.bt.xml.reader import load_tree_text
from bt_meta.cli import main
from bt_meta.errors import TreeXMLError

pytestmark = pytest.mark.usefixtures("clean_blackboard")
CALLS: list[str] = []


@action(inputs={"goal": str, "speed": float}, defaults={"speed": "0.5"}, outputs={"eta": float})
def PyMoveBase(goal: str, speed: float) -> dict:
    """Drive to a named goal."""
    CALLS.append(f"move {goal} {speed}")
    return {"eta": 3.0 / speed}


@condition(inputs={"target": str})
def PyIsVisible(target: str) -> bool:
    return target == "cup"


@action(name="PyWaitTwice")
class WaitTwice:
    def __init__(self) -> None:
        self.ticks = 0

    def tick(self) -> Status:
        self.ticks += 1
        return Status.SUCCESS if self.ticks % 3 == 0 else Status.RUNNING

    def halt(self) -> None:
        CALLS.append("halted")


def xml(body: str) -> str:
    return f'<root BTCPP_format="4"><BehaviorTree ID="M">{body}</BehaviorTree></root>'


def test_decorated_functions_are_nodes_with_their_ports() -> None:
    CALLS.clear()
    registry = domain_registry()
    node_type = registry.get("PyMoveBase")
    assert [(p.name, p.direction, p.type_name, p.default) for p in node_type.ports] == [
        ("goal", "input", "std::string", None),
        ("speed", "input", "double", "0.5"),
        ("eta", "output", "double", None),
    ]
    assert node_type.description == "Drive to a named goal."
    root = load_tree_text(
        xml('<Sequence><PyIsVisible target="cup"/><PyMoveBase goal="kitchen" eta="{eta}"/>'
            '<PyMoveBase goal="hall" speed="{eta}"/></Sequence>'),
        registry,
    )
    assert tick_once(root) == Status.SUCCESS
    assert CALLS == ["move kitchen 0.5", "move hall 6.0"]
    assert py_trees.blackboard.Blackboard.storage["/eta"] == 6.0
    assert tick_once(load_tree_text(xml('<PyIsVisible target="bowl"/>'), registry)) == Status.FAILURE


def test_a_decorated_class_can_run_and_be_halted() -> None:
    CALLS.clear()
    registry = domain_registry()
    root = load_tree_text(xml('<ReactiveSequence><PyWaitTwice/><PyWaitTwice/></ReactiveSequence>'), registry)
    assert tick_once(root) == Status.RUNNING
    root.stop(Status.INVALID)
    assert CALLS == ["halted"]


def test_ports_are_checked_at_load() -> None:
    with pytest.raises(TreeXMLError) as info:
        load_tree_text(xml('<PyMoveBase goal="a" sped="1"/>'), domain_registry())
    assert info.value.message == "node 'PyMoveBase' has no port 'sped' (ports: goal, speed, eta)"


def test_a_plugin_file_with_decorated_functions_needs_no_hook(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    plugins = tmp_path / "plugins"
    plugins.mkdir()
    (plugins / "my_nodes.py").write_text(
        "from bt_meta.bt.python_nodes import action\n"
        "@action(inputs={'n': int})\n"
        "def CountTo(n):\n"
        "    return n > 2\n"
    )
    tree = tmp_path / "t.xml"
    tree.write_text(xml('<Sequence><CountTo n="3" _monitor="false"/><CountTo n="1" _monitor="false"/></Sequence>'))
    assert main(["tick", str(tree), "--ticks", "2"]) == 1
    assert capsys.readouterr().out.splitlines()[-1].startswith("FAILURE after 1 ticks")
