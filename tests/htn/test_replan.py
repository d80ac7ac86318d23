"""Replanning from a failed decomposition node keeps the executed prefix (ids and steps) and climbs up."""

from __future__ import annotations

import pytest

from bt_meta.errors import PlanningError
from bt_meta.htn import load_task_file, method_from_text, plan, problem_from_atoms, replan
from bt_meta.resources import shipped_tree


@pytest.fixture
def letters():
    return load_task_file(shipped_tree("letters.yaml"))


def executed_state(result, steps: int):
    """The symbolic state after executing the first ``steps`` primitives."""
    return result.tree.primitives()[steps].state_before


def bar_node(result):
    return next(n for n in result.tree.primitives() if n.task[1] == "b5")


def test_replan_from_a_failed_primitive_uses_a_refinement_and_keeps_the_prefix(letters):
    domain, problem = letters.domain, letters.problems["A"]
    first = plan(domain, problem)
    failed = bar_node(first)
    assert (failed.id, failed.step) == ("n8", 4)
    # the 1x2 block is gone; two new blue 1x1 blocks are on the table; a refinement says how to use them
    state = executed_state(first, 4).apply(
        add=[("available", b) for b in ("b6", "b7")] + [(p, b, v) for b in ("b6", "b7")
                                                         for p, v in (("shape", "1x1"), ("colour", "blue"))]
        + [("block", "b6"), ("block", "b7")],
        delete=[("available", "b5")])
    domain.add_method(method_from_text(
        domain, name="A_bar_two_1x1", task="draw_A_bar()",
        precondition="usable(?l, 1x1, blue) and usable(?r, 1x1, blue) and ?l != ?r",
        subtasks=["place(?l, 1, 1)", "place(?r, 2, 1)"]))
    result = replan(domain, first.tree, failed.id, state)
    assert result.status == "success", result.message
    assert [str(a) for a in result.plan] == [
        "place(b0, 0, 0)", "place(b1, 0, 1)", "place(b2, 3, 0)", "place(b3, 3, 1)",
        "place(b4, 1, 1)", "place(b6, 2, 1)", "place(b7, 1.5, 2)"]
    assert [a.node_id for a in result.plan[:4]] == [a.node_id for a in first.plan[:4]]
    assert result.stats["replanned_from"] == "n7" and result.stats["kept_steps"] == 4
    tree = result.tree
    new_ids = [a.node_id for a in result.plan[4:]]
    assert all(int(i[1:]) > 10 for i in new_ids)
    assert [p.step for p in tree.primitives()] == list(range(7))
    # the new draw_A_bar node took the old one's place under draw_A, before the replanned apex
    root = tree.nodes["n0"]
    labels = [tree.nodes[c].label() for c in root.children]
    assert labels == ["draw_leg(0)", "draw_leg(3)", "draw_A_bar()", "draw_apex()"]
    assert tree.nodes[root.children[2]].method == "A_bar_two_1x1"
    assert "n7" not in tree.nodes and "n8" not in tree.nodes


def test_replan_tries_the_remaining_bindings_of_the_same_method(letters):
    domain = letters.domain
    base = letters.problems["A"]
    init = [*base.init, ("available", "b6"), ("shape", "b6", "1x2"), ("colour", "b6", "blue"), ("block", "b6")]
    problem = problem_from_atoms(domain, "two_bars", init=init, tasks=base.tasks, objects=base.objects)
    first = plan(domain, problem)
    failed = bar_node(first)
    result = replan(domain, first.tree, failed.id, executed_state(first, 4))
    assert result.status == "success"
    assert str(result.plan[4]) == "place(b6, 1.5, 1)"
    bar = result.tree.nodes[result.tree.nodes["n0"].children[2]]
    assert (bar.method, bar.bindings) == ("A_bar_one_1x2", {"bar": "b6"})


def test_replan_climbs_to_the_ancestors_and_reports_what_it_tried(letters):
    domain, problem = letters.domain, letters.problems["A"]
    first = plan(domain, problem)
    failed = bar_node(first)
    state = executed_state(first, 4).apply(delete=[("available", "b5")])
    result = replan(domain, first.tree, failed.id, state)
    assert result.status == "no_plan"
    assert result.message.startswith("replan from n8 failed: tried n7, n0; no plan")
    assert result.stats["candidates_tried"] == ["n7", "n0"]


def test_replan_of_a_failed_root_primitive_replans_the_rest_of_the_network(letters):
    domain, base = letters.domain, letters.problems["A"]
    problem = problem_from_atoms(domain, "flat", init=base.init, objects=base.objects,
                                 tasks=[("place", "b0", "0", "0"), ("place", "b1", "0", "1")])
    first = plan(domain, problem)
    result = replan(domain, first.tree, first.plan[1].node_id, executed_state(first, 1))
    assert result.status == "success"
    assert [a.node_id for a in result.plan] == ["n0", "n2"]
    assert result.stats["replanned_from"] == "the task network"


def test_replan_checks_its_node_and_budget(letters):
    first = plan(letters.domain, letters.problems["A"])
    with pytest.raises(PlanningError, match="no node 'n99' in the decomposition tree"):
        replan(letters.domain, first.tree, "n99", letters.problems["A"].state)
    result = replan(letters.domain, first.tree, "n8", executed_state(first, 4), max_nodes=1)
    assert result.status == "budget_exhausted"
