"""The tree XML shipped in trees/: what `bt-meta compile` writes, loadable by BehaviorTree.CPP, runnable by us.

Each XML file is the compiled form of a shipped task file's problem; integrators open them in Groot2. They must
not go stale, must load in the real BehaviorTree.CPP (behaviortreepy) and must tick to SUCCESS in our engine.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from py_trees.common import Status

from bt_meta.cli import main
from bt_meta.resources import trees_dir
from bt_meta.testing import TreeHarness

# XML file -> (task file, problem, policy tree?)
SHIPPED = {
    "letters_A.xml": ("letters.yaml", "A", False),
    "letters_H.xml": ("letters.yaml", "H", False),
    "letters_policy.xml": ("letters.yaml", "A", True),
    "magnetic_attach_nominal.xml": ("magnetic_attach.yaml", "nominal", False),
    "housing_insertion_nominal.xml": ("housing_insertion.yaml", "nominal", False),
}


def test_every_xml_in_trees_is_known_here():
    assert {path.name for path in trees_dir().glob("*.xml")} == set(SHIPPED)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_xml_is_what_compile_writes(name, tmp_path, capsys):
    task_file, problem, policy = SHIPPED[name]
    out = tmp_path / name
    args = ["compile", str(trees_dir() / task_file), "--problem", problem, "-o", str(out), "--no-entry-points"]
    assert main([*args, "--policy"] if policy else args) == 0
    assert out.read_text(encoding="utf-8") == (trees_dir() / name).read_text(encoding="utf-8"), (
        f"trees/{name} is stale: regenerate it with bt-meta compile trees/{task_file} --problem {problem}"
        f"{' --policy' if policy else ''} -o trees/{name}")


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_xml_loads_and_ticks_in_behaviortree_cpp(name, btcpp_tick_order):
    document = ET.fromstring((trees_dir() / name).read_text(encoding="utf-8"))
    model = document.find("TreeNodesModel")
    assert model is not None, "Groot2 needs a TreeNodesModel entry for every custom node"
    custom = {element.get("ID"): element.tag for element in model}
    assert custom, "a compiled tree declares its primitives and guards"
    document.remove(model)
    ticked = btcpp_tick_order(document, custom)  # asserts the tree ticks to SUCCESS
    assert ticked, "the primitives ran"


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_xml_runs_to_success_on_the_fake_world(name, bt_blackboard):
    task_file, problem, _ = SHIPPED[name]
    harness = TreeHarness.from_file(trees_dir() / name, problem, task_file=trees_dir() / task_file,
                                    entry_points=False)
    try:
        assert harness.tick_until("done", max_ticks=500) is Status.SUCCESS
        assert harness.failures == []
    finally:
        harness.close()
