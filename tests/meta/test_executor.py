"""The repair loop on the fake world: retry, replan from a node, budgets, motion limits, contained plugins."""

from __future__ import annotations

import dataclasses
import json
import time
from typing import Any

import pytest

from bt_meta.bt.failures import FailureKind, RepairProposal
from bt_meta.errors import BtMetaError
from bt_meta.meta import Limits, MetaExecutor, run_task_file
from bt_meta.plugins import hookimpl
from bt_meta.world.fake import FakeWorld, Fault

from .conftest import ScriptedWorld, make_host


def _actions(report):
    return [attempt.proposal["action"] for attempt in report.attempts]


def test_a_scripted_skill_failure_is_repaired_by_retry(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["put(b0, 0, 0)#1=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host()).run()
    assert report.ok, report.stop_reason
    assert _actions(report) == ["retry"]
    attempt = report.attempts[0]
    assert (attempt.kind, attempt.step, attempt.outcome) == ("physical", 1, "repaired")
    assert attempt.proposal["plugin"] == "retry_repair"
    # the executed prefix (pick b0) is not run again: the retry resumes at the failed put
    assert [(e["step"], e["status"]) for e in report.executed] == [
        (0, "SUCCESS"), (1, "FAILURE"), (1, "SUCCESS"), (2, "SUCCESS"), (3, "SUCCESS")]
    assert [s.record()["action"] for s in world.executed] == ["pick", "put", "put", "pick", "put"]
    assert report.plan == report.initial_plan
    assert report.failures[0]["kind"] == "physical"
    assert report.segments == 2 and report.seconds > 0 and report.ticks > 0


def test_a_silent_failure_is_caught_by_the_monitor_classified_and_retried(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["pick(b1)#1=silent"])
    report = MetaExecutor(blocks.domain, problem, world, make_host()).run()
    assert report.ok
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("physical", "retry")]
    failure = report.failures[0]
    assert failure["evidence"]["classified_by"] == "classification_rules"
    assert failure["evidence"]["mismatches"][0]["evidence"]["missing"] == ["held(b1)"]


class StealAfterFirstPut:
    """Someone takes block b1 off the table while the robot puts b0 down (and, if ``seen``, the robot sees it)."""

    def __init__(self, seen: bool = False) -> None:
        self.seen = seen

    @hookimpl
    def bt_meta_trace_event(self, event: dict[str, Any]) -> None:
        if event["type"] == "step_end" and event["action"] == "put" and event["status"] == "SUCCESS":
            from bt_meta.bt.context import current_run

            run = current_run()
            run.world.apply_symbolic(add=[], delete=[("on_table", "b1")])
            if self.seen:
                run.state = run.world.symbolic_state()


def test_a_method_guard_catches_a_precondition_the_robot_saw_change_and_its_node_is_replanned(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem)
    report = MetaExecutor(blocks.domain, problem, world, make_host(("thief", StealAfterFirstPut(True)))).run()
    assert report.ok, report.stop_reason
    failure = report.failures[0]
    # the guard of put_at(1, 0)'s method fails before its pick starts; the reasoner localises it to step 2
    assert (failure["kind"], failure["node_id"], failure["step"]) == ("precondition", "n4", None)
    assert failure["evidence"]["bindings"]["b"] == "b1"
    assert failure["evidence"]["localisation"] == {"step": 2, "node_id": "n4", "ancestors": [
        {"id": "n0", "task": ["draw"], "method": "draw_two"}]}
    assert report.attempts[0].proposal["changes"] == {"node_id": "n4"}
    assert [(e["segment"], e["step"], e["status"]) for e in report.executed] == [
        (1, 0, "SUCCESS"), (1, 1, "SUCCESS"), (2, 2, "SUCCESS"), (2, 3, "SUCCESS")]
    assert [(a.proposal["action"], a.outcome) for a in report.attempts] == [("replan", "repaired")]
    assert report.plan[2:] == [["pick", "b2"], ["put", "b2", "1", "0"]]
    assert [s.record()["args"][0] for s in world.executed] == ["b0", "b0", "b2", "b2"]  # pick(b1) never started


def test_a_precondition_failure_is_repaired_by_replanning_from_its_node(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem)
    report = MetaExecutor(blocks.domain, problem, world, make_host(("thief", StealAfterFirstPut()))).run()
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("precondition", "replan")]
    assert report.attempts[0].proposal["changes"]["node_id"] == report.failures[0]["node_id"]
    assert "replanned from" in report.attempts[0].change
    assert report.initial_plan[2:] == [["pick", "b1"], ["put", "b1", "1", "0"]]
    assert report.plan == [["pick", "b0"], ["put", "b0", "0", "0"], ["pick", "b2"], ["put", "b2", "1", "0"]]
    assert ("at", "b2", "1", "0") in world.symbolic_state()
    # the belief still had b1 on the table: the world refused pick(b1); it is not retried
    assert [(s.record()["action"], s.record()["args"][0], s.record()["outcome"]) for s in world.executed] == [
        ("pick", "b0", "SUCCESS"), ("put", "b0", "SUCCESS"), ("pick", "b1", "FAILURE"), ("pick", "b2", "SUCCESS"),
        ("put", "b2", "SUCCESS")]


def test_attempts_are_bounded(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["pick=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(), limits=Limits(max_attempts=1)).run()
    assert report.status == "failed"
    assert len(report.attempts) == 1 and report.attempts[0].outcome == "failed_again"
    assert "attempt budget spent (1 repair attempt(s))" in report.stop_reason
    assert report.reported[0]["kind"] == "physical"


def test_time_is_bounded(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["pick=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(), limits=Limits(max_seconds=1e-9),
                          plan_seconds=5).run()
    assert report.status == "failed" and report.attempts == []
    assert report.stop_reason.startswith("time budget spent")


def test_ticks_are_bounded_and_the_running_skill_is_cancelled(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, ticks_per_skill={"put": 50})
    report = MetaExecutor(blocks.domain, problem, world, make_host(), limits=Limits(max_ticks=10)).run()
    assert report.status == "failed" and report.ticks == 10
    assert report.failures[0]["message"] == "tick budget spent (10 ticks) while ticking"
    assert report.failures[0]["evidence"]["budget"] == "tick"
    assert world.executed[1].cancelled
    assert (report.failures[0]["step"], report.failures[0]["action"]) == (1, "put")  # the step that was running
    assert report.attempts == [] and report.stop_reason == "tick budget spent (10 ticks)"


def test_wall_time_is_bounded_while_ticking(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, ticks_per_skill={"pick": 10**9})
    report = MetaExecutor(blocks.domain, problem, world, make_host(), limits=Limits(max_seconds=0.2)).run()
    assert report.status == "failed" and report.attempts == []
    assert report.failures[0]["message"] == "time budget spent (0.2 s wall time) while ticking"
    assert report.stop_reason.startswith("time budget spent")
    assert world.executed[0].cancelled


def test_cpu_time_budget_bounds_ticking_and_ignores_waiting(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, ticks_per_skill={"pick": 10**9})
    report = MetaExecutor(blocks.domain, problem, world, make_host(),
                          limits=Limits(max_seconds=0.2, clock="cpu")).run()
    assert report.failures[0]["message"] == "time budget spent (0.2 s cpu time) while ticking"
    limits = Limits(clock="cpu")
    before = limits.now()
    time.sleep(0.3)  # a loaded machine: the process waits, its CPU clock does not run
    assert limits.now() - before < 0.1


def test_bad_limits_are_refused():
    with pytest.raises(BtMetaError, match="bad repair limits"):
        Limits(max_attempts=-1)
    with pytest.raises(BtMetaError, match="clock 'sundial'"):
        Limits(clock="sundial")


class StubbornRetry:
    """A careless plugin: retries everything, collisions included."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal]:
        return [RepairProposal("retry", 0.9, "try again", changes={"n": 1})]


class OtherCell:
    """Proposes moving the put to another cell -- which collides too."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal]:
        if failure.action != "put":
            return []
        return [RepairProposal("rewrite_args", 0.8, "put it next door",
                               changes={"args": [failure.args[0], "1", "1"]})]


@pytest.mark.parametrize(("kind", "evidence", "shown"), [
    ("collision", {"colliding_pair": ["right_gripper", "b1"], "distance": -0.004}, "colliding_pair"),
    ("reachability", {"unreachable_target": [0.9, -0.8, 0.2, 0, 3.14, 0], "ik": "failed"}, "unreachable_target"),
])
def test_motion_limits_are_reported_once_with_evidence_and_never_retried(blocks, kind, evidence, shown):
    problem = blocks.problem("two")
    world = ScriptedWorld(blocks.domain, problem, scripted={"put": (kind, f"scripted {kind}", evidence)})
    report = MetaExecutor(blocks.domain, problem, world, make_host(("stubborn", StubbornRetry()))).run()
    assert report.status == "failed"
    assert report.attempts == []
    assert world.scripted_starts == 1
    assert [f["kind"] for f in report.failures] == [kind]
    assert len(report.reported) == 1
    assert report.reported[0]["kind"] == kind and report.reported[0]["evidence"][shown] == evidence[shown]
    assert "reported with its evidence" in report.stop_reason


def test_a_motion_limit_that_recurs_after_a_repair_stops_the_loop(blocks):
    # no goal: putting b0 next door would otherwise drop at(b0, 0, 0) and be refused (tests/meta/test_invariants.py)
    problem = dataclasses.replace(blocks.problem("two"), goal=[])
    evidence = {"colliding_pair": ["right_gripper", "b1"]}
    world = ScriptedWorld(blocks.domain, problem, scripted={"put": ("collision", "gripper hits b1", evidence)})
    report = MetaExecutor(blocks.domain, problem, world, make_host(("other_cell", OtherCell()))).run()
    assert report.status == "failed"
    assert _actions(report) == ["rewrite_args"]
    assert world.scripted_starts == 2
    assert "collision again at step 1 after a repair" in report.stop_reason
    assert report.reported == [{"kind": "collision", "step": 1, "node_id": report.failures[-1]["node_id"],
                                "action": "put", "args": ["b0", "1", "1"], "message": "gripper hits b1",
                                "evidence": {"colliding_pair": ["right_gripper", "b1"]},
                                "tried": [{"attempt": 1, "action": "rewrite_args", "plugin": "other_cell",
                                           "description": "put it next door", "change": "step 1 now put(b0, 1, 1)",
                                           "outcome": "failed_again",
                                           "why": "then failed: [collision] step 1 put(b0, 1, 1): gripper hits b1"}]}]


class Broken:
    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal]:
        raise ValueError("no idea")


def test_a_plugin_raising_in_propose_repairs_is_contained_as_internal(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["pick#1=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(("broken", Broken()))).run()
    assert report.ok
    assert _actions(report) == ["retry"]
    internal = [f for f in report.failures if f["kind"] == "internal"]
    assert len(internal) == 1
    assert internal[0]["plugin"] == "broken"
    assert "raised in bt_meta_propose_repairs: ValueError: no idea" in internal[0]["message"]


def test_a_failed_verification_triggers_a_repair(blocks):
    problem = blocks.problem("one")
    # The put "succeeds" but b0 stays in the hand: without perception the monitor believes the effects, only the
    # verification (the goal in the world) sees it.
    fault = Fault("put", mode="partial", args=("b0", "0", "0"), occurrence=1,
                  drop=(("at", "b0", "0", "0"), ("held", "b0")))
    world = FakeWorld(blocks.domain, problem, faults=[fault])
    report = MetaExecutor(blocks.domain, problem, world, make_host(perception=False)).run()
    assert report.failures[0]["kind"] == "verification"
    assert report.failures[0]["evidence"]["missing"] == ["at(b0, 0, 0)"]
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"], a.step) for a in report.attempts] == [
        ("verification", "replan", 1)]
    assert "replanned from n0" in report.attempts[0].change  # put_at(0, 0), re-decomposed by put_held
    # the repaired plan replaces the failed put; what ran shows both
    assert report.plan == [["pick", "b0"], ["put", "b0", "0", "0"]]
    assert [(e["action"], e["status"]) for e in report.executed] == [
        ("pick", "SUCCESS"), ("put", "SUCCESS"), ("put", "SUCCESS")]
    assert ("at", "b0", "0", "0") in world.symbolic_state()


def test_no_proposal_means_stop_with_the_failure_reported(blocks):
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["pick#1=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(retry=False)).run()
    assert report.status == "failed" and report.attempts == []
    assert report.stop_reason == "no repair proposed for physical at step 0"


def test_no_plan_is_reported(blocks):
    problem = dataclasses.replace(blocks.problem("two"), goal=[("at", "b0", "1", "1")])
    world = FakeWorld(blocks.domain, problem)
    report = MetaExecutor(blocks.domain, problem, world, make_host()).run()
    assert report.status == "no_plan" and report.stop_reason == "no plan for the problem"
    assert report.message.startswith("no_plan: ") and world.executed == []


def test_run_task_file_with_the_fake_world(tmp_path):
    from .conftest import BLOCKS

    path = tmp_path / "blocks.yaml"
    path.write_text(BLOCKS, encoding="utf-8")
    report = run_task_file(path, "two", plugins=make_host(), faults=["pick#2=fail:physical"])
    assert report.ok and _actions(report) == ["retry"]
    record = json.loads(json.dumps(report.to_dict()))
    assert record["attempts"][0]["kind"] == FailureKind.PHYSICAL.value
    assert record["repairs"][0]["action"] == "retry" and record["status"] == "success"


def test_a_replan_that_yields_the_failed_plan_again_is_not_applied_twice(blocks):
    """Every pick fails: a replan from the new node of the failed step plans the same steps again; it is the same
    attempt (same steps, same objects), so the executor stops saying so instead of spending its budget."""
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["pick=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(), limits=Limits(max_attempts=8)).run()
    assert not report.ok
    assert "repeat attempt(s) 1: not looped on" in report.stop_reason
    assert "replan_scratch (retry_repair): equivalent to attempt 1" in report.stop_reason
    assert len(report.attempts) < 8
    assert [a.proposal["action"] for a in report.attempts] == ["retry"]
    assert report.reported and report.reported[0]["kind"] == "physical"
    tried = report.reported[0]["tried"]  # what was tried for the unrepaired failure, and why each did not repair
    assert tried[0]["attempt"] == 1 and tried[0]["action"] == "retry" and tried[0]["outcome"] == "failed_again"
    assert "then failed: [physical] step 0 pick(b0)" in tried[0]["why"]
    assert [(t["action"], t["outcome"]) for t in tried[1:]] == [("replan", "not_applied"),
                                                               ("replan_scratch", "not_applied")]
    assert tried[2]["why"].startswith("equivalent to attempt 1")


def test_an_unkept_attempt_a_later_one_overwrote_does_not_block_the_refinement():
    """``keep: False`` says the attempt's plan does not replay from the start; once a deeper backtrack rewrote its
    poses, nothing of it is in the final plan, and it no longer stops the refinement from being saved."""
    from bt_meta.meta.kept_plan import survives as _survives
    from bt_meta.meta.reasoner import Attempt

    def attempt(action: str, changes: dict) -> Attempt:
        return Attempt(1, {}, "verification", {"action": action, "changes": changes, "evidence": {"keep": False}},
                       "", 5, 0.0)

    plan = [["MoveTo", "above"], ["MoveTo", "held:ref:0:0:0.1:0:0:0"], ["Grasp"]]
    assert _survives(attempt("backtrack", {"to_step": 1, "args": {"1": ["held:ref:0:0:0.1:0:0:0"]}}), plan)
    assert not _survives(attempt("backtrack", {"to_step": 1, "args": {"1": ["held:ref:0:0:0.2:0:0:0"]}}), plan)
    assert _survives(attempt("splice", {"start": 0, "end": 1, "actions": [["MoveTo", "x"]]}), plan)  # assumed kept
