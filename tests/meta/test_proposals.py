"""Each proposal kind applied to a real decomposition tree; proposals that cannot apply say why."""

from __future__ import annotations

import pytest

from bt_meta.bt.failures import RepairProposal
from bt_meta.htn import plan
from bt_meta.meta.proposals import PlanState, ProposalError, apply_proposal, proposal_key


@pytest.fixture
def planned(blocks):
    problem = blocks.problem("two")
    result = plan(blocks.domain, problem)
    assert [(a.name, a.args) for a in result.plan] == [
        ("pick", ("b0",)), ("put", ("b0", "0", "0")), ("pick", ("b1",)), ("put", ("b1", "1", "0"))]
    return blocks.domain, problem, PlanState(result.tree, 2)


def _apply(planned, action, changes=None, failed_step=2, **options):
    domain, problem, state = planned
    node = state.step_node(failed_step).id
    return apply_proposal(RepairProposal(action, 1.0, changes=changes or {}), state, failed_step=failed_step,
                          failed_node=node, domain=domain, problem=problem, state=problem.state, **options)


def _plan(state):
    return [[name, *args] for name, args in state.full_plan()]


def test_retry_resumes_at_the_failed_step(planned):
    new, change = _apply(planned, "retry", failed_step=3)
    assert (new.cursor, change) == (3, "retry step 3") and _plan(new) == _plan(planned[2])


def test_rewrite_args_checks_arity_and_refuses_earlier_steps(planned):
    new, change = _apply(planned, "rewrite_args", {"args": ["b2"]})
    assert change == "step 2 now pick(b2)" and new.cursor == 2
    assert _plan(new)[2] == ["pick", "b2"] and _plan(planned[2])[2] == ["pick", "b1"]  # the old plan is untouched
    assert new.unguarded  # the put_any node chose b1: its guard is not checked again
    with pytest.raises(ProposalError, match=r"pick takes 1 argument\(s\), got 2"):
        _apply(planned, "rewrite_args", {"args": ["b2", "b3"]})
    with pytest.raises(ProposalError, match="before the failed step 2: use backtrack"):
        _apply(planned, "rewrite_args", {"step": 0, "args": ["b2"]})


def test_substitute_renames_from_the_failed_step_on(planned):
    new, change = _apply(planned, "substitute", {"mapping": {"b1": "b2"}})
    assert change == "substitute b1 -> b2 in 2 step(s)"
    assert _plan(new) == [["pick", "b0"], ["put", "b0", "0", "0"], ["pick", "b2"], ["put", "b2", "1", "0"]]
    compound = new.tree.nodes[new.tree.nodes[new.step_node(2).id].parent]
    assert compound.bindings["b"] == "b2"
    with pytest.raises(ProposalError, match="no step from 2 on uses these objects"):
        _apply(planned, "substitute", {"mapping": {"b9": "b2"}})
    with pytest.raises(ProposalError, match="non-empty 'mapping'"):
        _apply(planned, "substitute", {})


def test_backtrack_rewinds_the_cursor_with_new_arguments(planned):
    new, change = _apply(planned, "backtrack", {"to_step": 0, "args": {"0": ["b2"], "1": ["b2", "0", "0"]}})
    assert new.cursor == 0
    assert change == "backtrack to step 0; step 0 now pick(b2); step 1 now put(b2, 0, 0)"
    with pytest.raises(ProposalError, match="must be between 0 and the failed step 2"):
        _apply(planned, "backtrack", {"to_step": 3})
    with pytest.raises(ProposalError, match="cannot change the earlier step 0"):
        _apply(planned, "backtrack", {"to_step": 1, "args": {"0": ["b2"]}})
    with pytest.raises(ProposalError, match="needs 'to_step'"):
        _apply(planned, "backtrack", {})


def test_splice_replaces_steps_and_renumbers(planned):
    new, change = _apply(planned, "splice", {"start": 2, "end": 4, "actions": [["pick", "b2"], ["put", "b2", "1",
                                                                                                 "0"]]})
    assert change == "steps 2..3 replaced by pick(b2), put(b2, 1, 0)"
    assert [n.step for n in new.steps()] == [0, 1, 2, 3]
    assert _plan(new)[2:] == [["pick", "b2"], ["put", "b2", "1", "0"]]
    assert len({n.id for n in new.steps()}) == 4
    longer, _ = _apply(planned, "splice", {"start": 3, "end": 4, "actions": [["put", "b1", "1", "0"],
                                                                             ["pick", "b2"]]}, failed_step=3)
    assert [n.step for n in longer.steps()] == [0, 1, 2, 3, 4] and _plan(longer)[-1] == ["pick", "b2"]
    with pytest.raises(ProposalError, match="unknown primitive 'fly'"):
        _apply(planned, "splice", {"actions": [["fly"]]})


def test_replan_keeps_the_prefix_and_reports_failures(planned, blocks):
    domain, problem, state = planned
    world_state = problem.state.apply(add=[("at", "b0", "0", "0")], delete=[("on_table", "b0"), ("on_table", "b1")])
    node = state.step_node(2).id
    new, change = apply_proposal(RepairProposal("replan", 1, changes={}), state, failed_step=2, failed_node=node,
                                 domain=domain, problem=problem, state=world_state)
    assert change.startswith("replanned from") and new.cursor == 2
    assert _plan(new) == [["pick", "b0"], ["put", "b0", "0", "0"], ["pick", "b2"], ["put", "b2", "1", "0"]]
    empty = problem.state.apply(add=[], delete=[("on_table", "b1"), ("on_table", "b2")])
    with pytest.raises(ProposalError, match=r"replan from n\d+: no_plan"):
        apply_proposal(RepairProposal("replan", 1), state, failed_step=2, failed_node=node, domain=domain,
                       problem=problem, state=empty.apply(add=[], delete=[("on_table", "b0")]))
    with pytest.raises(ProposalError, match="no such decomposition node"):
        _apply(planned, "replan", {"node_id": "n999"})


def test_replan_from_scratch_commits_the_executed_prefix(planned):
    new, change = _apply(planned, "replan_scratch")
    assert change.startswith("planned the task network afresh")
    assert new.cursor == 0 and new.committed == [("pick", ("b0",)), ("put", ("b0", "0", "0"))]
    assert len(new.full_plan()) == 2 + len(new.steps())


def test_unknown_kinds_and_keys(planned):
    with pytest.raises(ProposalError, match="unknown proposal kind 'teleport'; expected one of: retry, "):
        _apply(planned, "teleport")
    a = RepairProposal("retry", 0.1, "x", {"n": 1})
    b = RepairProposal("retry", 0.9, "y", {"n": 1}, plugin="other")
    assert proposal_key(a) == proposal_key(b) != proposal_key(RepairProposal("retry", 0.1, changes={"n": 2}))


def test_remaining_tree_drops_guards_of_started_tasks(planned):
    _, _, state = planned
    remaining = state.remaining_tree()
    assert [n.step for n in remaining.primitives()] == [2, 3]
    root = remaining.nodes[remaining.roots[0]]
    assert root.method is None  # draw() started already
    second = remaining.nodes[remaining.nodes[state.step_node(2).id].parent]
    assert second.method == "put_any"  # put_at(1, 0) has not started: its guard stays


def test_rebind_changes_no_step_but_is_part_of_the_attempt_s_effect(planned):
    from bt_meta.meta.proposals import plan_effect

    retry, _ = _apply(planned, "retry")
    new, change = _apply(planned, "rebind", {"symbols": {"b1": "spare"}})
    assert change == "rebind b1 -> spare; resume at step 2"
    assert (new.cursor, new.rebound) == (2, {"b1": "spare"}) and _plan(new) == _plan(planned[2])
    assert plan_effect(new) != plan_effect(retry)  # the same steps on another object are another attempt
    again = apply_proposal(RepairProposal("substitute", 1.0, changes={"mapping": {"b1": "b2"}}), new, failed_step=2,
                           failed_node=new.step_node(2).id, domain=planned[0], problem=planned[1],
                           state=planned[1].state)[0]
    assert again.rebound == {"b1": "spare"}  # later repairs keep the rebinding
    with pytest.raises(ProposalError, match="bound so already"):
        apply_proposal(RepairProposal("rebind", 1.0, changes={"symbols": {"b1": "spare"}}), new, failed_step=2,
                       failed_node=new.step_node(2).id, domain=planned[0], problem=planned[1],
                       state=planned[1].state)
    with pytest.raises(ProposalError, match="non-empty"):
        _apply(planned, "rebind", {})
    with pytest.raises(ProposalError, match="between 0 and the failed step"):
        _apply(planned, "rebind", {"symbols": {"b1": "spare"}, "from_step": 3})
