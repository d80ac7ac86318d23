"""The goal is invariant under repair, whatever plugin proposes (fake world): hand-written plugins that try to
rewrite, skip or drop a verification step, or to weaken the goal, are refused by the executor with the reason in
the report; a repair of how the task is done still applies; a stored refinement whose goal is weaker than the
problem's, or whose plan leaves a verification step out, is not planned with."""

from __future__ import annotations

from typing import Any

import pytest

from bt_meta.bt.failures import RepairProposal
from bt_meta.htn import load_task_text
from bt_meta.meta import MetaExecutor, RefinementStore
from bt_meta.meta.invariants import missing_verifications, touched_entities, weakened_goal
from bt_meta.meta.refinements import Refinement, pose_precondition
from bt_meta.plugins import hookimpl
from bt_meta.world.fake import FakeWorld

from .conftest import make_host

DELIVER = """
domain:
  name: deliver
  types: [pose]
  predicates:
    at: [pose]
  primitives:
    MoveTo:
      parameters: [?p - pose]
      precondition: at(?from)
      add: [at(?p)]
      delete: [at(?from)]
  tasks:
    Deliver: []
    Show: []
    VerifyDelivery: []
  methods:
    - name: deliver_and_show
      task: Deliver()
      subtasks: [MoveTo(pick), MoveTo(place), Show()]
    - name: show_it
      task: Show()
      subtasks: [MoveTo(show)]
    - name: deliver_and_verify
      task: VerifyDelivery()
      subtasks: [MoveTo(pick), MoveTo(place), MoveTo(show)]
problems:
  shown:
    objects: {pose: [home, pick, place, show, elsewhere]}
    init: [at(home)]
    tasks: [Deliver()]
    goal: [at(show)]
  verified:
    objects: {pose: [home, pick, place, show, elsewhere]}
    init: [at(home)]
    tasks: [VerifyDelivery()]
    goal: []
"""


class CheckedWorld(FakeWorld):
    """A fake world whose grounding declares a check on the pose ``show`` (as ``verify_lifted`` does)."""

    def declared_checks(self, symbol: str) -> list[str]:
        return ["verify_lifted"] if symbol == "show" else []


class RewriteTheCheck:
    """Tries to make a failed check pass by going somewhere else instead (the tutorial's false success)."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        return [RepairProposal("rewrite_args", 0.9, "go elsewhere instead",
                               changes={"step": failure.step, "args": ["elsewhere"]})]


class DropTheCheck:
    """Tries to splice the checking step away."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        return [RepairProposal("splice", 0.8, "stay where it is",
                               changes={"start": failure.step, "end": failure.step + 1,
                                        "actions": [["MoveTo", "place"]]})]


class PlaceElsewhere:
    """Tries to put the part down elsewhere when putting it down failed: the goal at(place) would be dropped."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        return [RepairProposal("rewrite_args", 0.9, "put it elsewhere",
                               changes={"step": failure.step, "args": ["elsewhere"]})]


class BackUpAndRetry:
    """A repair of how the task is done: go back to the pick and come again, every step as it was."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        return [RepairProposal("backtrack", 0.5, "from the pick again", changes={"to_step": 0, "args": {}})]


@pytest.fixture
def deliver():
    return load_task_text(DELIVER, "<deliver>")


def _run(task: Any, problem_name: str, *plugins: Any, world_type: type = CheckedWorld,
         faults: tuple[str, ...] = ("MoveTo(show)#1=fail:verification",), store: Any = None) -> Any:
    problem = task.problem(problem_name)
    world = world_type(task.domain, problem, faults=list(faults))
    host = make_host(*((type(p).__name__, p) for p in plugins), retry=False)
    return MetaExecutor(task.domain, problem, world, host, refinements=store).run()


@pytest.mark.parametrize("cheat", [RewriteTheCheck(), DropTheCheck()])
def test_a_plugin_that_rewrites_or_drops_a_declared_check_is_refused(deliver, cheat):
    report = _run(deliver, "shown", cheat)
    assert report.status == "failed" and report.attempts == []
    assert len(report.refused) == 1
    assert report.refused[0]["reason"] == "it would rewrite, skip or drop the verification step(s) MoveTo(show)"
    assert "refused: it would rewrite, skip or drop the verification step(s) MoveTo(show)" in report.stop_reason
    tried = report.reported[0]["tried"]
    assert tried[0]["outcome"] == "not_applied" and tried[0]["why"].startswith("refused: ")


def test_the_steps_of_a_verify_task_are_verification_steps(deliver):
    report = _run(deliver, "verified", RewriteTheCheck(), world_type=FakeWorld)
    assert report.status == "failed" and report.refused
    assert report.refused[0]["reason"].endswith("MoveTo(show)")


def test_a_plugin_that_weakens_the_goal_is_refused(deliver):
    report = _run(deliver, "shown", PlaceElsewhere(), world_type=FakeWorld, faults=("MoveTo(show)#1=fail:physical",))
    assert report.status == "failed"
    assert report.refused[0]["reason"] == "it would weaken the goal: at(show) no longer reached"


def test_a_repair_of_how_the_task_is_done_applies_and_the_check_runs(deliver):
    report = _run(deliver, "shown", RewriteTheCheck(), BackUpAndRetry())
    assert report.ok, report.stop_reason
    assert [a.proposal["action"] for a in report.attempts] == ["backtrack"]
    assert report.plan[-1] == ["MoveTo", "show"] and report.refused


def test_a_stored_refinement_weaker_than_the_problem_is_not_planned_with(deliver, tmp_path):
    problem = deliver.problem("shown")
    with RefinementStore.open(tmp_path / "m.sqlite") as store:
        # as the tutorial's false success stored it: the check rewritten, the goal with it
        store.add(Refinement(domain="deliver", task="Deliver()", method="refined_weaker_goal",
                             precondition=pose_precondition({}, store.tolerance),
                             subtasks=["MoveTo(pick)", "MoveTo(place)", "MoveTo(elsewhere)"],
                             goal=[["at", "elsewhere"]]))
        store.add(Refinement(domain="deliver", task="Deliver()", method="refined_no_check",
                             precondition="true", subtasks=["MoveTo(pick)", "MoveTo(place)"]))
        world = CheckedWorld(deliver.domain, problem)
        report = MetaExecutor(deliver.domain, problem, world, make_host(), refinements=store).run()
    assert report.ok and report.refinements_used == []
    reasons = {r["method"]: r["reason"] for r in report.refinements_skipped}
    assert reasons["refined_weaker_goal"] == "its goal is weaker than the problem's: at(show) dropped"
    assert reasons["refined_no_check"] == "its plan leaves out the verification step(s) MoveTo(show)"


def test_goal_facts_are_restated_only_for_entities_a_repair_changed():
    goal = [("at", "b5", "1.5", "1"), ("at", "show")]
    rewritten = [("at", "b5", "1", "1"), ("at", "b6", "2", "1"), ("at", "show")]
    assert weakened_goal(goal, rewritten, touched_entities([("shape", "b5", "1x1")])) == []
    assert weakened_goal(goal, rewritten, set()) == [("at", "b5", "1.5", "1")]
    assert weakened_goal(goal, [("at", "held:base:0:0:0:0:0:0")], {"b5"}) == [("at", "show")]
    assert touched_entities([("at", "b0", "1", "1")], [{"p": "s_blue"}]) == {"b0", "p", "s_blue"}
    assert missing_verifications([("MoveTo", "show")], [("MoveTo", "a"), ("MoveTo", "show")]) == []
    assert missing_verifications([("MoveTo", "show")], [("MoveTo", "held:base:0:0:0:0:0:0")]) == [("MoveTo", "show")]
