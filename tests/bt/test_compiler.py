"""The compiler: decomposition trees and method libraries to monitored py_trees trees."""

from __future__ import annotations

import pytest
from py_trees.common import Status

from bt_meta.bt.actions import PrimitiveAction
from bt_meta.bt.compiler import CompileError, compile_plan, compile_policy, compile_task_file
from bt_meta.bt.context import RunContext
from bt_meta.bt.guards import CheckCondition
from bt_meta.bt.monitor import Monitor
from bt_meta.bt.xml import tree_to_xml
from bt_meta.htn import load_task_text, plan
from bt_meta.plugins import create_plugin_host
from bt_meta.testing import TreeHarness
from bt_meta.world.fake import FakeWorld

TASKS = """
domain:
  name: blocks
  types: [block, cell]
  predicates:
    on_table: [block]
    red: [block]
    at: [block, cell, cell]
    hand_empty: []
    held: [block]
  primitives:
    pick:
      parameters: [?b - block]
      precondition: on_table(?b) and hand_empty()
      add: [held(?b)]
      delete: [on_table(?b), hand_empty()]
    put:
      parameters: [?b - block, ?x - cell, ?y - cell]
      precondition: held(?b)
      add: [at(?b, ?x, ?y), hand_empty()]
      delete: [held(?b)]
  tasks:
    place: [?b - block, ?x - cell, ?y - cell]
    draw: []
    clear: []
  methods:
    - name: place_by_pick_put
      task: place(?b, ?x, ?y)
      precondition: on_table(?b)
      subtasks: [pick(?b), put(?b, ?x, ?y)]
    - name: draw_red_first
      task: draw()
      precondition: red(?a) and on_table(?a) and on_table(?c) and ?a != ?c
      subtasks: [place(?a, 0, 0), place(?c, 1, 0)]
    - name: draw_any
      task: draw()
      precondition: on_table(?a) and on_table(?c) and ?a != ?c
      subtasks: [place(?a, 1, 1), place(?c, 0, 1)]
    - name: clear_one
      task: clear()
      precondition: on_table(?b)
      subtasks: [place(?b, 0, 0), clear()]
    - name: clear_done
      task: clear()
      precondition: not on_table(b0)
      subtasks: []
problems:
  red:
    objects: {block: [b0, b1], cell: [0, 1]}
    init: [on_table(b0), on_table(b1), red(b1), hand_empty()]
    tasks: [draw()]
  plain:
    objects: {block: [b0, b1], cell: [0, 1]}
    init: [on_table(b0), on_table(b1), hand_empty()]
    tasks: [draw()]
"""


@pytest.fixture
def task_file():
    return load_task_text(TASKS, "<test>")


def _run(root, task_file, problem, **world_options):
    domain = task_file.domain
    chosen = task_file.problem(problem)
    world = FakeWorld(domain, chosen, **world_options)
    run = RunContext(world, create_plugin_host(), domain=domain, problem=chosen).install()
    for _ in range(100):
        if run.tick(root) is not Status.RUNNING:
            break
    return run, world


def test_plan_tree_keeps_node_ids_guards_and_monitors(task_file, bt_blackboard):
    result = plan(task_file.domain, task_file.problem("red"))
    root = compile_plan(result.tree, task_file.domain, name="plan red")
    names = [b.name for b in root.iterate()]
    assert "n0 draw()" in names and "n1 place(b1, 0, 0)" in names and "n2 pick(b1)" in names
    assert "n0 guard draw_red_first" in names
    actions = [b for b in root.iterate() if isinstance(b, PrimitiveAction)]
    assert [(a.node_id, a.step, a.action) for a in actions] == [
        ("n2", 0, "pick"), ("n3", 1, "put"), ("n5", 2, "pick"), ("n6", 3, "put")]
    assert all(isinstance(a.parent, Monitor) for a in actions)
    guard = next(b for b in root.iterate() if isinstance(b, CheckCondition) and b.name.startswith("n0"))
    assert guard.bindings == {"a": "b1", "c": "b0"}
    for behaviour in root.iterate():
        if not getattr(behaviour, "is_monitor", False):
            assert behaviour.bt_node is not None, behaviour.name
    assert actions[1].bt_node.id == "put" and actions[1].bt_node.ports == {"b": "b1", "x": "0", "y": "0"}
    run, world = _run(root, task_file, "red")
    assert root.status is Status.SUCCESS and run.failures == []
    assert ("at", "b1", "0", "0") in world.symbolic_state()


def test_plan_guard_fails_when_the_world_changed(task_file, bt_blackboard):
    compiled = compile_task_file(task_file, "red")
    domain = task_file.domain
    world = FakeWorld(domain, task_file.problem("red"))
    world.apply_symbolic(add=[], delete=[("red", "b1")])
    run = RunContext(world, create_plugin_host(), domain=domain).install()
    assert run.tick(compiled.root) is Status.FAILURE
    [failure] = run.failures
    assert failure.kind.value == "precondition" and failure.node_id == "n0"
    assert "draw_red_first" in failure.message


def test_policy_tree_chooses_methods_at_run_time(task_file, bt_blackboard):
    root = compile_policy(task_file.domain, task_file.problem("plain").tasks)
    run, world = _run(root, task_file, "plain")
    assert root.status is Status.SUCCESS and run.failures == []
    # draw_red_first's guard fails (no red block), so draw_any ran: b0 at (1, 1), b1 at (0, 1).
    assert ("at", "b0", "1", "1") in world.symbolic_state() and ("at", "b1", "0", "1") in world.symbolic_state()
    bt_blackboard.clear()
    root = compile_policy(task_file.domain, task_file.problem("red").tasks)
    run, world = _run(root, task_file, "red")
    assert ("at", "b1", "0", "0") in world.symbolic_state()


def test_policy_tree_recursion_is_cut_at_the_depth_limit(task_file, bt_blackboard):
    root = compile_policy(task_file.domain, [("clear",)], max_depth=3)
    names = [b.name for b in root.iterate()]
    assert any(name.endswith("depth limit 3") for name in names)
    run, _world = _run(root, task_file, "plain")
    assert run.failures == []
    assert root.status is Status.SUCCESS  # two blocks need clear() twice, then clear_done
    with pytest.raises(CompileError, match="exceeds 50 nodes"):
        compile_policy(task_file.domain, [("clear",)], max_depth=30, max_nodes=50)


def test_compiled_xml_loads_back_and_ticks_the_same(task_file, tmp_path, bt_blackboard):
    (tmp_path / "blocks.yaml").write_text(TASKS)
    compiled = compile_task_file(tmp_path / "blocks.yaml", "red")
    xml = tree_to_xml(compiled.root, tree_id="Plan_red", registry=compiled.registry)
    (tmp_path / "blocks.xml").write_text(xml)
    direct = TreeHarness.from_file(tmp_path / "blocks.yaml", "red", ticks_per_skill=2)
    direct_statuses = [(direct.tick().value, direct.statuses()) for _ in range(5)]
    bt_blackboard.clear()
    loaded = TreeHarness.from_file(tmp_path / "blocks.xml", "red", ticks_per_skill=2)
    loaded_statuses = [(loaded.tick().value, loaded.statuses()) for _ in range(5)]
    assert loaded_statuses == direct_statuses
    assert loaded.root.status is Status.SUCCESS
    action = loaded.node("n5", raw=True)
    assert (action.node_id, action.step) == ("n5", 2)


def test_unknown_primitive_in_a_decomposition_is_a_compile_error(task_file):
    result = plan(task_file.domain, task_file.problem("red"))
    node = next(n for n in result.tree.nodes.values() if n.kind == "primitive")
    node.task = ("teleport", "b0")
    with pytest.raises(CompileError, match="unknown primitive 'teleport'"):
        compile_plan(result.tree, task_file.domain)


def _btcpp_order(compiled, tree_id, btcpp_tick_order):
    """Tick the compiled tree's XML once in the real BehaviorTree.CPP (behaviortreepy), every custom node a
    SUCCESS-returning simple node registered without ports (behaviortreepy cannot declare ports), and return the
    names of the custom nodes in the order BT.CPP ticked them."""
    import xml.etree.ElementTree as ET

    document = ET.fromstring(tree_to_xml(compiled.root, tree_id=tree_id, registry=compiled.registry))
    custom = {node_type.id: node_type.category for node_type in compiled.registry.custom_types()}
    return btcpp_tick_order(document, custom)


@pytest.mark.parametrize("policy", [False, True])
def test_compiled_letters_load_and_tick_in_behaviortree_cpp(policy, bt_blackboard, btcpp_tick_order):
    from bt_meta.resources import shipped_tree

    compiled = compile_task_file(shipped_tree("letters.yaml"), "A", policy=policy)
    btcpp = _btcpp_order(compiled, "Policy_A" if policy else "Plan_A", btcpp_tick_order)
    harness = TreeHarness(compiled.root, RunContext(FakeWorld(compiled.domain, compiled.problem),
                                                    create_plugin_host(), domain=compiled.domain))
    assert harness.tick() is Status.SUCCESS
    ours = [name for name, node in harness.statuses().items()
            if isinstance(harness.node(name, raw=True), (PrimitiveAction, CheckCondition))]
    if policy:
        # BT.CPP's stand-in guards always succeed, ours fail for methods that do not fit: compare primitives only.
        btcpp = [name for name in btcpp if " guard " not in name]
        ours = [name for name in ours if " guard " not in name]
    assert ours == btcpp and len([n for n in ours if "place" in n]) == 6


@pytest.mark.parametrize(("primitive", "message"), [
    ("Sequence:\n      parameters: [?x]", "primitive 'Sequence' has the ID of a built-in node"),
    ("label:\n      parameters: [?name]", r"parameter \?name cannot be a BehaviorTree.CPP port name"),
])
def test_domains_that_cannot_become_node_types_are_refused(primitive, message):
    from bt_meta.bt.domain_nodes import domain_registry
    from bt_meta.bt.registry import RegistryError

    text = f"""
domain:
  name: clash
  predicates:
    p: [thing]
  primitives:
    {primitive}
      precondition: p(?{'x' if 'Sequence' in primitive else 'name'})
      add: []
      delete: []
"""
    with pytest.raises(RegistryError, match=message):
        domain_registry(load_task_text(text, "<clash>").domain)
