"""Runs a plan as a monitored behaviour tree on a world, and repairs it when it fails.

The loop (``docs/meta-reasoning.md``):

1. plan the problem (learned refinements first, when a :class:`~bt_meta.meta.refinements.RefinementStore` is
   given) and keep the plan as a :class:`~bt_meta.meta.proposals.PlanState`;
2. compile the steps not yet run into a py_trees tree (a Monitor around every primitive) and tick it through the
   :class:`~bt_meta.testing.TreeHarness` in one :class:`~bt_meta.bt.context.RunContext` for the whole run;
3. on FAILURE, or when the tree succeeds but verification fails (the problem's goal facts must hold in the world,
   plus any ``verifiers``), the :class:`~bt_meta.meta.reasoner.MetaReasoner` diagnoses and ranks proposals; the
   first that applies becomes the new plan state and execution continues from its cursor (the executed prefix is
   never run again unless a proposal backtracks into it);
4. stop on success, or when the reasoner stops (budgets, a recurring motion limit, nothing proposed);
5. on a success that needed repairs, save the repaired plan as a method refinement, with the entity facts the
   repairs wrote into the world's symbolic state from perception and the goal as the repairs rewrote it;
6. a learned refinement whose precondition holds at the start (its objects where they were, its entities seen as
   they were) has its perceived facts added to the world's and the problem's state before planning, and a run
   that uses it is verified against its rewritten goal;
7. every proposal is checked before it applies (:mod:`bt_meta.meta.invariants`): one that would rewrite, skip or
   drop a verification step, or weaken the goal, is refused (``RunReport.refused``); a stored refinement that would
   is not planned with (``RunReport.refinements_skipped``), nor one of another robot or demoted;
8. a plan from learned refinements that fails on replay -- unless it is an objection the refinement's own run met
   at that step (``RunReport.expected``) -- demotes them and falls back to the hand-written methods
   (``RunReport.fallback``); a replay with zero attempts is counted;
9. a ``rebind`` repair (a grounding symbol grounded as a spare, :data:`~bt_meta.meta.proposals.REBIND`) is passed
   to the world (``world.rebind_object``) before the plan runs again, and kept with the refinement: a refinement
   whose precondition holds rebinds the same symbols before planning.

Offers:

* :class:`MetaExecutor` -- :meth:`~MetaExecutor.run` returns a :class:`RunReport`
* :class:`RunReport` -- status, attempts, failures, repairs, reported failures, final plan, time, ticks
* :func:`goal_verifier` -- the default verification: the problem's goal facts hold in the world's symbolic state
* :func:`run_task_file` -- load a task file, build the fake or a plugin's world, run with repairs
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from py_trees.common import Status

from bt_meta.bt.actions import PrimitiveAction
from bt_meta.bt.compiler import compile_plan
from bt_meta.bt.context import RunContext
from bt_meta.bt.domain_nodes import domain_registry
from bt_meta.bt.failures import Failure, FailureKind
from bt_meta.errors import BtMetaError, PluginError, UnknownWorldError
from bt_meta.htn.state import atom_text
from bt_meta.meta.invariants import missing_verifications, touched_entities, verification_calls, weakened_goal
from bt_meta.meta.kept_plan import replaced_steps, replayed, unkept_attempts
from bt_meta.meta.proposals import PlanState, ProposalError, apply_proposal, plan_effect, proposal_facts
from bt_meta.meta.reasoner import Attempt, Decision, Diagnosis, Limits, MetaReasoner

__all__ = ["MetaExecutor", "RunReport", "Verifier", "goal_verifier", "run_task_file"]

log = logging.getLogger("bt_meta.meta")

Verifier = Callable[[Any, RunContext, PlanState], "Failure | None"]
"""``verifier(world, run, plan_state)`` -> a ``verification`` :class:`Failure`, or ``None`` when verified."""


def goal_verifier(world: Any, run: RunContext, plan_state: PlanState) -> Failure | None:
    """The problem's goal facts must hold in the world's (true) symbolic state after the plan."""
    goal = list(getattr(run.problem, "goal", None) or [])
    if not goal:
        return None
    truth = world.symbolic_state()
    missing = [atom for atom in goal if atom not in truth]
    if not missing:
        return None
    steps = plan_state.steps()
    last = steps[-1] if steps else None
    return Failure(kind=FailureKind.VERIFICATION,
                   message="every step succeeded but the goal does not hold: missing "
                           + ", ".join(atom_text(a) for a in missing),
                   step=None if last is None else last.step, node_id=None if last is None else last.id,
                   action=None if last is None else last.task[0],
                   args=() if last is None else tuple(last.task[1:]),
                   evidence={"missing": [atom_text(a) for a in missing], "verifier": "goal"})


@dataclass
class RunReport:
    """The outcome of one repaired run."""

    status: str
    """``"success"``, ``"failed"`` (not repaired) or ``"no_plan"``."""
    problem: str | None
    attempts: list[Attempt] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    reported: list[dict[str, Any]] = field(default_factory=list)
    """Failures the run ended with, not repaired; collision and reachability carry their evidence."""
    plan: list[list[str]] = field(default_factory=list)
    initial_plan: list[list[str]] = field(default_factory=list)
    executed: list[dict[str, Any]] = field(default_factory=list)
    stop_reason: str = ""
    seconds: float = 0.0
    ticks: int = 0
    segments: int = 0
    refinements_used: list[str] = field(default_factory=list)
    refinement_saved: dict[str, Any] | None = None
    message: str = ""
    rebound: dict[str, str] = field(default_factory=dict)
    """Grounding symbols the run grounded as other world objects (repairs, or a refinement that kept them)."""
    refused: list[dict[str, Any]] = field(default_factory=list)
    """Proposals refused because they would change what counts as done (a verification step, the goal), with why."""
    refinements_skipped: list[dict[str, str]] = field(default_factory=list)
    """Stored refinements not planned with, with why (demoted, another robot's, weaker than the problem)."""
    refinements_demoted: list[str] = field(default_factory=list)
    expected: list[dict[str, Any]] = field(default_factory=list)
    """Monitor objections a used refinement's learning run met at the same steps, which its plan goes on through."""
    fallback: dict[str, Any] | None = None
    """When a learned plan failed on replay: the refinements demoted, the step, and what the run went on with."""
    robot: str | None = None

    @property
    def repairs(self) -> list[dict[str, Any]]:
        """The applied proposals, in order."""
        return [attempt.proposal for attempt in self.attempts]

    @property
    def ok(self) -> bool:
        return self.status == "success"

    def to_dict(self) -> dict[str, Any]:
        return {
            "status": self.status, "problem": self.problem, "stop_reason": self.stop_reason,
            "message": self.message, "seconds": round(self.seconds, 6), "ticks": self.ticks,
            "segments": self.segments, "attempts": [a.to_dict() for a in self.attempts], "repairs": self.repairs,
            "failures": self.failures, "reported": self.reported, "initial_plan": self.initial_plan,
            "plan": self.plan, "executed": self.executed, "refinements_used": self.refinements_used,
            "refinement_saved": self.refinement_saved, "rebound": self.rebound, "refused": self.refused,
            "refinements_skipped": self.refinements_skipped, "refinements_demoted": self.refinements_demoted,
            "fallback": self.fallback, "robot": self.robot, "expected": self.expected,
        }


class MetaExecutor:
    """Plans, runs, diagnoses and repairs one problem on one world; see the module docstring.

    ``refinements`` (a :class:`~bt_meta.meta.refinements.RefinementStore`) makes learned refinements of the
    problem's tasks the first methods tried, and receives the repaired plan of a successful repaired run
    (``save_refinements=False`` to only use them). ``verifiers`` replace the default goal check. ``memory`` (an
    :class:`~bt_meta.memory.EpisodicMemory`) becomes the run's ``memory``, where plugins look for their traces.
    """

    def __init__(
        self,
        domain: Any,
        problem: Any,
        world: Any,
        plugins: Any,
        *,
        limits: Limits | None = None,
        reasoner: MetaReasoner | None = None,
        refinements: Any = None,
        save_refinements: bool = True,
        verifiers: Iterable[Verifier] | None = None,
        task_file: Any = None,
        variant: str | None = None,
        plan_seconds: float | None = None,
        memory: Any = None,
    ) -> None:
        self.base_domain = domain
        self.problem = problem
        self.world = world
        self.plugins = plugins
        self.limits = limits or (reasoner.limits if reasoner is not None else Limits())
        self.reasoner = reasoner or MetaReasoner(plugins, self.limits)
        self.refinements = refinements
        self.save_refinements = save_refinements
        self.verifiers = list(verifiers) if verifiers is not None else [goal_verifier]
        self.task_file = task_file
        self.variant = variant
        self.plan_seconds = plan_seconds
        self.memory = memory

    # -- the loop ------------------------------------------------------------------------------------------------

    def run(self) -> RunReport:
        from bt_meta.htn import plan

        started = self.limits.now()  # the budget clock (wall or CPU time); report.seconds is wall time
        wall_started = time.perf_counter()
        name = getattr(self.problem, "name", None)
        report = RunReport(status="failed", problem=name)
        domain = self.base_domain
        added: list[str] = []
        stored: dict[str, Any] = {}
        robot = _robot_name(self.world)
        report.robot = robot
        if self.refinements is not None:
            domain, added, stored = self._learned(report, robot)
        planned = _declare_symbols(self.world, domain, added, self.problem)
        run = RunContext(self.world, self.plugins, domain=domain, problem=self.problem, task_file=self.task_file)
        if self.memory is not None:
            run.memory = self.memory  # what expectation and repair plugins read (context.run.memory)
        run.install()  # external predicates (pose tolerance of refinements) read the world through the run
        # Perceived entity facts of the refinements that apply here: known to the world and the planner (below).
        anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]] = (set(), set())
        assumed = planned.state  # what the problem assumed, before any perceived facts
        declared = planned  # the problem as the hand-written methods plan it (a fallback starts from it)
        planned = self._perceive(domain, [stored[n] for n in added if n in stored], planned, run, anchored,
                                 report.rebound)
        start_state = planned.state
        # the refinements' perceived facts (added, deleted): a fallback to the hand-written plan takes them back
        learned_facts = ({tuple(a) for a in planned.state} - {tuple(a) for a in declared.state},
                         {tuple(a) for a in declared.state} - {tuple(a) for a in planned.state})
        start_objects = _objects(self.world)
        run.start_objects = start_objects  # what repair plugins compare the start with (a part's first orientation)
        run.emit("run_start", task_file=getattr(self.task_file, "path", None), problem=name,
                 state=[atom_text(a) for a in sorted(run.state)])
        external = self.plugins.external_predicate
        plan_budget = self.plan_seconds if self.plan_seconds is not None else self.limits.max_seconds
        result = plan(domain, planned, external=external, max_seconds=plan_budget)
        if result.status != "success" or result.tree is None:
            report.status, report.message = "no_plan", f"{result.status}: {result.message}"
            report.stop_reason = "no plan for the problem"
            return self._finish(report, run, wall_started)
        plan_state = PlanState(result.tree, rebound=dict(report.rebound))
        report.refinements_used = [n.method for n in result.tree.walk() if n.method in added]
        report.initial_plan = [[a, *args] for a, args in plan_state.full_plan()]
        refined_goal = next((g for m in report.refinements_used if m in stored
                             and (g := stored[m].goal_atoms()) is not None), None)
        # verified against the goal the used refinement's repair rewrote, else the problem's own
        run.problem = dataclasses.replace(run.problem, goal=refined_goal if refined_goal is not None
                                          else list(getattr(self.problem, "goal", None) or []))
        base_goal = list(getattr(run.problem, "goal", None) or [])
        origin_plan = list(report.initial_plan)  # the plan repairs are measured against (the hand-written one after a
        # fallback from a refinement whose replay failed)
        registry = domain_registry(domain, self.plugins)
        tried: set[str] = set()
        effects: dict[str, int] = {}  # an applied attempt's effect (plan_effect) -> its number
        undone: list[tuple[str, ...]] = []  # facts applied proposals made false on purpose (changes["facts"])
        touched: list[dict[str, Any]] = [dict(report.rebound)]  # substitutions and rebindings applied
        # monitor objections the used refinements' learning runs met on the steps they replay through
        expected = [dict(e) for m in report.refinements_used if m in stored
                    for e in (stored[m].repair or {}).get("expected") or []]
        # perceived objects (world names and the task-file symbols for them): a repair that re-arranges them may
        # restate a goal fact about them (a re-tiling: the bar's cells covered by other blocks)
        names = _world_names(self.world, self.problem)
        perceived = set(start_objects) | {symbol for symbol, world_name in names.items() if world_name in start_objects}
        moved: set[str] = set()  # perceived objects whose steps applied repairs changed

        def guard(proposal: Any, before: PlanState, after: PlanState, failed_step: int) -> str | None:
            """Why ``proposal`` (``before`` -> ``after``) would change what counts as done, or ``None``."""
            return self._weakens(proposal, before, after, failed_step, domain, base_goal, origin_plan, start_state,
                                 anchored, undone, [*touched, {e: e for e in moved | _rearranged(before, after,
                                                                                                  perceived)}])

        while True:
            failures, status = self._segment(run, plan_state, registry, domain, report, started)
            if status is Status.SUCCESS:
                plan_state = dataclasses.replace(plan_state, cursor=len(plan_state.steps()))
                failures = [f for f in (v(self.world, run, plan_state) for v in self.verifiers) if f is not None]
                for failure in failures:
                    run.record_failure(failure)
                if not failures:
                    report.status = "success"
                    if report.attempts:
                        report.attempts[-1].outcome = "repaired"
                    break
            if report.attempts and report.attempts[-1].outcome == "pending":
                report.attempts[-1].outcome = "failed_again"
            if not failures:
                failures = [Failure(kind=FailureKind.INTERNAL, message="the tree failed without a failure record",
                                    step=plan_state.cursor)]
                run.record_failure(failures[0])
            if report.refinements_used and not report.attempts and report.fallback is None \
                    and (passed := _expected_by(failures, plan_state, expected)) is not None:
                # an objection the refinement's own learning run met at this step and its plan goes on through
                # (it replays the moves that run made before the repair): expected, the plan goes on
                report.expected.append(passed)
                run.emit("repair", outcome="expected", expected=passed,
                         reason=f"step {passed['step']}: the learned plan's own run met this objection here and went "
                                "on through it")
                plan_state = dataclasses.replace(plan_state, cursor=int(passed["step"]) + 1)
                continue
            if report.refinements_used and not report.attempts and report.fallback is None:
                # the learned plan failed on replay: demote it, go back to the plan it refined (the hand-written
                # methods' plan) and repair that, so a learned repair never turns a success into a failure
                fallback = self._fall_back(report, plan_state, failures, declared, run, external, plan_budget,
                                           learned_facts, anchored)
                if fallback is not None:
                    plan_state, origin_plan = fallback, [[a, *args] for a, args in fallback.full_plan()]
                    domain = self.base_domain
                    run.domain = domain
                    registry = domain_registry(domain, self.plugins)
                    base_goal = list(getattr(self.problem, "goal", None) or [])
                    run.problem = dataclasses.replace(run.problem, goal=list(base_goal))
                    continue
            diagnosis = self.reasoner.diagnose(failures, plan_state, run, report.attempts)
            if report.ticks >= self.limits.max_ticks:
                decision = Decision([], stop=True, reason=f"tick budget spent ({self.limits.max_ticks} ticks)")
            else:
                before = _symbolic(self.world)
                decision = self.reasoner.decide(diagnosis, run, plan_state, report.attempts, tried, started)
                _note_changes(anchored, before, _symbolic(self.world))  # what repair plugins anchored
            if decision.stop:
                report.stop_reason = decision.reason
                report.reported.append(_with_tried(self.reasoner.report_entry(diagnosis), report.attempts,
                                                   diagnosis, decision.dropped, []))
                for limit in decision.limits:
                    run.record_failure(limit)
                    report.reported.append(self.reasoner.limit_entry(limit, diagnosis))
                run.emit("repair", outcome="stopped", reason=decision.reason, diagnosis=diagnosis.to_dict(),
                         dropped=decision.dropped)
                break
            skipped: list[dict[str, Any]] = []
            applied = self._apply(decision.proposals, diagnosis, plan_state, run, domain, report, tried, started,
                                  effects, skipped, anchored, undone, guard)
            if applied is None:
                report.stop_reason = _unapplied_reason(diagnosis, skipped)
                report.reported.append(_with_tried(self.reasoner.report_entry(diagnosis), report.attempts,
                                                   diagnosis, decision.dropped, skipped))
                run.emit("repair", outcome="stopped", reason=report.stop_reason, diagnosis=diagnosis.to_dict(),
                         skipped=skipped)
                break
            _rebind(self.world, plan_state.rebound, applied.rebound)
            moved |= _rearranged(plan_state, applied, perceived)
            plan_state = applied
            touched.append(_mapping_of(report.attempts[-1].proposal))
            keep_goal = bool((report.attempts[-1].proposal.get("evidence") or {}).get("keep_goal"))
            if base_goal and not keep_goal:  # the goal as the repair rewrote it (spliced placements stand for the
                # replaced ones); a proposal that only prepares a later repair (keep_goal) leaves the goal alone
                goal = self._rewritten_goal(domain, base_goal, origin_plan,
                                            [[a, *args] for a, args in plan_state.full_plan()], start_state, anchored,
                                            _still_undone(domain, undone, plan_state))
                run.problem = dataclasses.replace(run.problem, goal=goal)
        report.plan = [[a, *args] for a, args in plan_state.full_plan()]
        report.rebound = dict(plan_state.rebound)
        if report.status == "success" and report.refinements_used and not report.attempts \
                and report.fallback is None and self.refinements is not None:
            for method in report.refinements_used:  # replayed with zero attempts
                self._note_replay(method, succeeded=True)
        if report.status == "success" and report.attempts and self.refinements is not None and self.save_refinements:
            # kept unless a repair says its plan does not replay from the start (bt_meta.meta.kept_plan)
            unkept = unkept_attempts(report.attempts, report.plan)
            if unkept:  # a repair that worked from where this run stood, not from the initial state
                report.refinement_saved = {"saved": False, "reason": f"attempt(s) {unkept}: the proposing plugin says "
                                                                     "the repaired plan does not replay from the start"}
            else:
                # kept: how what was perceived differs from what the problem assumed at the start
                facts = ({f for f in anchored[0] if f not in assumed}, {f for f in anchored[1] if f in assumed})
                replayed_report = replayed(report)
                goal = list(getattr(run.problem, "goal", None) or [])
                if replayed_report.plan != report.plan and base_goal:
                    # the goal the replayed plan reaches: a block a repair set aside is not moved in a replay
                    goal = self._rewritten_goal(domain, base_goal, origin_plan, replayed_report.plan,
                                                start_state, anchored)
                weak = weakened_goal(base_goal, goal, touched_entities([*anchored[0], *anchored[1]],
                                                                       [*touched, {e: e for e in moved}]))
                if weak:
                    report.refinement_saved = {"saved": False, "reason": "the replayed plan would weaken the goal: "
                                               + ", ".join(atom_text(g) for g in weak) + " no longer reached"}
                elif report.fallback is not None and replayed_report.plan == origin_plan and not report.rebound:
                    # what ran is the hand-written plan the fallback went back to, retried where it failed
                    report.refinement_saved = {"saved": False, "reason": (
                        f"the learned plan ({', '.join(report.fallback['refinements'])}) failed on replay and was "
                        "demoted; the run went back to the hand-written plan, which reached the goal with retries "
                        "alone: nothing new to keep")}
                else:
                    refines = origin_plan
                    if report.fallback is None and report.refinements_used:  # repaired on top of a refinement
                        refines = next((stored[m].refines for m in report.refinements_used
                                        if m in stored and stored[m].refines), origin_plan)
                    report.refinement_saved = self._save_refinement(domain, replayed_report, start_objects, facts,
                                                                    goal, report.rebound, robot, refines,
                                                                    _passed_through(report.attempts,
                                                                                    replayed_report.plan))
        return self._finish(report, run, wall_started)

    def _perceive(self, domain: Any, refinements: list[Any], problem: Any, run: RunContext,
                  anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]],
                  rebound: dict[str, str] | None = None) -> Any:
        """``problem`` (and the world's symbolic state) with the perceived entity facts of every refinement whose
        precondition holds now -- its objects where they were, its entities seen as they were -- so the planner
        checks the refinement's steps against what is seen (two red 1x1 blocks, not the blue 1x2 the problem
        assumed). A refinement whose precondition fails adds nothing: the facts are not confirmed."""
        apply = getattr(self.world, "apply_symbolic", None)
        methods = {m.name: m for m in domain.methods}
        goal_set = False
        for refinement in refinements:
            add, delete = refinement.fact_atoms()
            method = methods.get(refinement.method)
            symbols = refinement.rebind_symbols()
            goal = refinement.goal_atoms()
            if not (add or delete or symbols or goal is not None) or method is None:
                continue
            try:
                holds = method.precondition.holds(problem.state, {}, self.plugins.external_predicate)
            except BtMetaError as error:
                log.info("meta: refinement %s: precondition not checkable: %s", refinement.method, error)
                continue
            if not holds:
                continue
            if symbols and rebound is not None and not rebound:  # the first that holds (they are tried in order)
                log.info("meta: refinement %s applies; it rebinds %s", refinement.method, symbols)
                _rebind(self.world, {}, symbols)
                rebound.update(symbols)
            if add or delete:
                log.info("meta: refinement %s applies; its perceived facts join the state: +%s -%s",
                         refinement.method, ", ".join(atom_text(a) for a in add),
                         ", ".join(atom_text(a) for a in delete))
                if apply is not None:
                    apply(add=add, delete=delete)
                state = problem.state.apply(add=add, delete=delete)
                init = [a for a in problem.init if tuple(a) not in set(delete)]
                problem = dataclasses.replace(problem, init=[*init, *(a for a in add if a not in problem.state)],
                                              state=state)
                _note_changes(anchored, set(), set(add))
                _note_changes(anchored, set(delete), set())
            # a refinement that restates the goal (a part moved elsewhere, nothing perceived about it) is planned
            # towards that goal too: the planner would else refuse its plan for the problem's goal
            if goal is not None and not goal_set:  # the planner checks the goal: the one this refinement achieves
                problem = dataclasses.replace(problem, goal=goal)
                goal_set = True
        symbolic = getattr(self.world, "symbolic_state", None)
        if symbolic is not None:
            run.state = symbolic()
        run.problem = problem
        return problem

    def _segment(self, run: RunContext, plan_state: PlanState, registry: Any, domain: Any, report: RunReport,
                 started: float) -> tuple[list[Failure], Status]:
        """Tick the steps from the cursor on until the tree finishes or a budget runs out; returns the new failures
        and the tree's status."""
        from bt_meta.testing import TreeHarness

        report.segments += 1
        first = len(run.failures)
        remaining = plan_state.remaining_tree()
        steps = {n.step: n for n in plan_state.steps()}
        if not remaining.roots:
            return [], Status.SUCCESS
        root = compile_plan(remaining, domain, registry=registry,
                            name=f"plan {report.problem} segment {report.segments}")
        harness = TreeHarness(root, run)
        deadline = started + self.limits.max_seconds
        ticks_left = self.limits.max_ticks - report.ticks
        status = Status.RUNNING
        while status is Status.RUNNING and len(harness.history) < ticks_left and self.limits.now() < deadline:
            status = harness.tick()
        report.ticks += len(harness.history)
        if status is Status.RUNNING:  # a budget ran out mid-step: cancel the running skill, say which budget
            running = next((b for b in root.iterate() if isinstance(b, PrimitiveAction)
                            and b.status is Status.RUNNING), None)
            root.stop(Status.INVALID)
            budget = "tick" if len(harness.history) >= ticks_left else "time"
            limit = (f"{self.limits.max_ticks} ticks" if budget == "tick"
                     else f"{self.limits.max_seconds} s {self.limits.clock} time")
            run.record_failure(Failure(
                kind=FailureKind.INTERNAL, message=f"{budget} budget spent ({limit}) while ticking",
                step=None if running is None else running.step, node_id=None if running is None else running.node_id,
                action=None if running is None else running.action,
                args=() if running is None or running.context is None else tuple(running.context.args),
                evidence={"budget": budget, "ticks": report.ticks}))
            status = Status.FAILURE
        failures = run.failures[first:]
        last = len(steps) if status is Status.SUCCESS else _failed_step(failures, plan_state)
        for step in range(plan_state.cursor, min(last, len(steps))):
            node = steps[step]
            report.executed.append({"segment": report.segments, "step": step, "action": node.task[0],
                                    "args": list(node.task[1:]), "node_id": node.id, "status": "SUCCESS"})
        failed = next((f for f in reversed(failures) if f.step is not None and f.step in steps), None)
        if status is not Status.SUCCESS and failed is not None and failed.step == last:
            node = steps[last]
            report.executed.append({"segment": report.segments, "step": last, "action": node.task[0],
                                    "args": list(node.task[1:]), "node_id": node.id, "status": "FAILURE"})
        return failures, status

    def _apply(self, proposals: list[Any], diagnosis: Diagnosis, plan_state: PlanState, run: RunContext,
               domain: Any, report: RunReport, tried: set[str], started: float, effects: dict[str, int],
               skipped: list[dict[str, Any]],
               anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]],
               undone: list[tuple[str, ...]],
               guard: Callable[[Any, PlanState, PlanState, int], str | None] | None = None) -> PlanState | None:
        """The plan state of the first proposal that applies and does something no earlier attempt did;
        ``skipped`` receives the others with why (not applicable, refused by ``guard`` -- it would change what
        counts as done, also listed in ``report.refused`` -- or equivalent to attempt N). The applied proposal's
        ``facts`` (:func:`_apply_facts`) join the world's symbolic state and ``anchored``."""
        # Repairs start from what the world is, not from what the failed run believed.
        symbolic = getattr(self.world, "symbolic_state", None)
        if symbolic is not None:
            run.state = symbolic()
        for proposal in proposals:
            key = self.reasoner.key(proposal, diagnosis)
            tried.add(key)
            attempt_started = time.perf_counter()
            remaining = max(self.limits.max_seconds - (self.limits.now() - started), 0.001)
            try:
                new_state, change = apply_proposal(
                    proposal, plan_state, failed_step=diagnosis.step, failed_node=diagnosis.node_id,
                    domain=domain, problem=self.problem, state=run.state, external=self.plugins.external_predicate,
                    max_seconds=remaining)
            except ProposalError as error:
                log.info("meta: %s proposal of %s not applicable: %s", proposal.action, proposal.plugin, error)
                run.emit("repair", outcome="not_applicable", proposal=proposal.to_dict(), reason=str(error))
                skipped.append({"proposal": proposal.to_dict(), "reason": f"not applicable: {error}"})
                continue
            refusal = None if guard is None else guard(proposal, plan_state, new_state, diagnosis.step)
            if refusal is not None:
                reason = f"refused: {refusal}"
                log.info("meta: %s proposal of %s %s", proposal.action, proposal.plugin, reason)
                run.emit("repair", outcome="refused", proposal=proposal.to_dict(), reason=reason)
                skipped.append({"proposal": proposal.to_dict(), "reason": reason})
                report.refused.append({"proposal": proposal.to_dict(), "step": diagnosis.step,
                                       "kind": diagnosis.kind.value, "reason": refusal})
                continue
            effect = plan_effect(new_state)
            if effect in effects:  # the identity of an attempt is what it does, not the node id it names
                number = effects[effect]
                reason = f"equivalent to attempt {number}: it would run the same steps from the same point"
                log.info("meta: %s proposal of %s skipped: %s", proposal.action, proposal.plugin, reason)
                run.emit("repair", outcome="equivalent", proposal=proposal.to_dict(), equivalent_to=number,
                         reason=reason)
                skipped.append({"proposal": proposal.to_dict(), "reason": reason, "equivalent_to": number})
                continue
            attempt = Attempt(number=len(report.attempts) + 1, failure=diagnosis.failure.to_dict(),
                              kind=diagnosis.kind.value, proposal=proposal.to_dict(), change=change,
                              step=diagnosis.step, seconds=round(time.perf_counter() - attempt_started, 6),
                              replaced=replaced_steps(proposal, plan_state, diagnosis.step))
            attempt.failure.pop("evidence", None)
            attempt.failure["evidence_keys"] = sorted(diagnosis.failure.evidence)
            if (signature := _monitor_signature(diagnosis.failure)) is not None:
                attempt.failure["monitor"] = signature
            report.attempts.append(attempt)
            effects[effect] = attempt.number
            log.info("meta: attempt %d: %s (%s, score %.2f, %s) -> %s", attempt.number, proposal.action,
                     proposal.plugin, proposal.score, proposal.description, change)
            run.emit("repair", outcome="applied", attempt=attempt.to_dict())
            if _apply_facts(self.world, proposal, anchored, undone) and symbolic is not None:
                run.state = symbolic()
            return new_state
        return None

    def _rewritten_goal(self, domain: Any, goal: list[Any], initial_plan: list[list[str]], plan: list[list[str]],
                        start_state: Any, anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]],
                        undone: Iterable[tuple[str, ...]] = ()) -> list[tuple[str, ...]]:
        """The goal ``plan`` reaches where ``initial_plan`` reached ``goal`` (:func:`rewrite_goal`), from the start
        state with the anchored facts."""
        from bt_meta.meta.refinements import rewrite_goal

        return rewrite_goal(domain, goal, initial_plan, plan, start_state,
                            start_state.apply(add=anchored[0], delete=anchored[1]), self.plugins.external_predicate,
                            undone=undone)

    def _save_refinement(self, domain: Any, report: RunReport, start_objects: dict[str, Any],
                         anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]],
                         goal: list[Any], rebound: dict[str, str] | None = None, robot: str | None = None,
                         refines: list[list[str]] | None = None,
                         expected: list[dict[str, Any]] | None = None) -> dict[str, Any] | None:
        from bt_meta.meta.refinements import RefinementError

        listing = getattr(self.refinements, "list", None)
        before = set() if listing is None else {r.id for r in listing(domain=self.base_domain.name)}
        try:
            saved = self.refinements.save_repair(self.base_domain, self.problem, report, start_objects,
                                                 variant=self.variant, names=_world_names(self.world, self.problem),
                                                 facts=(sorted(anchored[0]), sorted(anchored[1])), goal=goal,
                                                 rebind=rebound or None, robot=robot, refines=refines,
                                                 expected=expected or None)
        except RefinementError as error:
            log.info("meta: repaired plan not saved as a refinement: %s", error)
            return {"saved": False, "reason": str(error)}
        if saved is None:
            return None
        out = saved.to_dict()
        if saved.id in before:  # an equivalent refinement is stored already: kept once
            out["kept_once"] = f"equivalent to the stored {saved.method}; not stored again"
        return out

    # -- learned refinements: which to plan with, and the fallback when a replay fails ----------------------------

    def _learned(self, report: RunReport, robot: str | None) -> tuple[Any, list[str], dict[str, Any]]:
        """The domain with the learned refinements this run may plan with first, their names, and them by name.
        Skipped (``report.refinements_skipped``, with why): demoted ones, another robot's, and any whose goal is
        weaker than the problem's or whose plan leaves out a verification step of the hand-written plan."""
        candidates = getattr(self.refinements, "candidates", None)
        if candidates is None:  # a store of another kind: as it offers them
            domain, added = self.refinements.apply(self.base_domain, self.problem)
            listing = getattr(self.refinements, "list", None)
            stored = {} if listing is None else {r.method: r for r in listing(domain=domain.name) if r.method in added}
            return domain, added, stored
        fitting, skipped = candidates(self.base_domain, robot)
        refused = [{"method": r.method, "reason": why} for r in fitting
                   if (why := self._weaker_refinement(r)) is not None]
        report.refinements_skipped = skipped + refused
        excluded = [r["method"] for r in refused]
        domain, added = self.refinements.apply(self.base_domain, self.problem, robot=robot, exclude=excluded)
        stored = {r.method: r for r in fitting if r.method in added}
        return domain, added, stored

    def _weaker_refinement(self, refinement: Any) -> str | None:
        """Why ``refinement`` would change what counts as done, or ``None``: its goal drops a fact of the problem's
        without an entity it perceived or rebound to account for it, or its plan leaves out a verification step
        of the hand-written plan."""
        goal = refinement.goal_atoms()
        problem_goal = list(getattr(self.problem, "goal", None) or [])
        add, delete = refinement.fact_atoms()
        base = self._base_plan()
        if goal is not None:
            # the entities the learning run's guard let the goal be restated for: those whose facts it perceived,
            # those it rebound, and the perceived objects its plan moves otherwise than the hand-written plan (a
            # re-tiling's blocks) -- the same rule as when the repair applied, so a refinement that was saved
            # is also planned with
            moved = set() if base is None else _rearranged_calls(
                [tuple(str(a) for a in n.task) for n in base.steps()],
                [_call_of(s) for s in refinement.subtasks], self._perceived())
            weak = weakened_goal(problem_goal, goal, touched_entities([*add, *delete],
                                                                      [refinement.rebind_symbols(),
                                                                       {e: e for e in moved}]))
            if weak:
                return "its goal is weaker than the problem's: " + ", ".join(atom_text(g) for g in weak) + " dropped"
        if base is None:
            return None
        needed = [atom_text(c) for c in verification_calls(self.world, base)]
        missing = missing_verifications([(c,) for c in needed], [(str(s),) for s in refinement.subtasks])
        if missing:
            return "its plan leaves out the verification step(s) " + ", ".join(m[0] for m in missing)
        return None

    def _perceived(self) -> set[str]:
        """The objects the world reports at the start, and the task-file symbols grounded as them (observed once
        for all the stored refinements)."""
        if getattr(self, "_perceived_at_start", None) is None:
            objects = _objects(self.world)
            names = _world_names(self.world, self.problem)
            self._perceived_at_start = set(objects) | {symbol for symbol, name in names.items() if name in objects}
        return self._perceived_at_start

    def _base_plan(self, problem: Any = None) -> PlanState | None:
        """The hand-written methods' plan of the problem from its initial state (``problem``: another start)."""
        from bt_meta.htn import plan

        if problem is None and getattr(self, "_base", False) is not False:
            return self._base
        budget = self.plan_seconds if self.plan_seconds is not None else self.limits.max_seconds
        try:
            result = plan(self.base_domain, problem or self.problem, external=self.plugins.external_predicate,
                          max_seconds=budget)
        except BtMetaError as error:
            log.info("meta: the hand-written methods do not plan the problem: %s", error)
            result = None
        found = None if result is None or result.status != "success" or result.tree is None \
            else PlanState(result.tree)
        if problem is None:
            self._base = found
        return found

    def _fall_back(self, report: RunReport, plan_state: PlanState, failures: list[Failure], planned: Any,
                   run: RunContext, external: Any, budget: float,
                   learned_facts: tuple[set[tuple[str, ...]], set[tuple[str, ...]]] = (set(), set()),
                   anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]] | None = None) -> PlanState | None:
        """After the first failure of a plan from learned refinements: demote them, and the plan state to go on
        with -- the hand-written plan at the failed step when the learned plan ran as it does up to there, else
        the hand-written methods planned from the state the world is in now (``None`` when they plan nothing:
        the learned plan is then repaired as it stands). The hand-written plan is the one of ``planned``, the
        problem as declared, and going on with it from the failed step takes the demoted refinements' perceived
        facts (``learned_facts``: added, deleted) back out of the world's state: with them (a 1x2 bar believed a
        1x1) the hand-written methods do not apply, and the first exposure's own repair is never reached again;
        the repair perceives them again when it needs them."""
        from bt_meta.htn import plan

        failure = failures[-1]
        reason = f"its replay failed: [{failure.kind.value}] step {failure.step} {failure.message}"
        for method in report.refinements_used:
            self._note_replay(method, succeeded=False, reason=reason)
        report.refinements_demoted = list(report.refinements_used)
        learned = [[a, *args] for a, args in plan_state.full_plan()]
        failed = len(learned) if failure.kind is FailureKind.VERIFICATION and failure.step is None \
            else _failed_step(failures, plan_state)
        base = self._base_plan(dataclasses.replace(planned, goal=list(getattr(self.problem, "goal", None) or [])))
        fallback = None
        if base is not None:
            hand = [[a, *args] for a, args in base.full_plan()]
            same = next((i for i, (a, b) in enumerate(zip(learned, hand, strict=False)) if a != b),
                        min(len(learned), len(hand)))
            if failed <= same:  # nothing the refinement changed has run: the hand-written plan from here
                fallback = dataclasses.replace(base, cursor=min(failed, len(hand)), rebound=dict(plan_state.rebound))
                how = f"the hand-written plan from step {fallback.cursor}"
                added, deleted = learned_facts
                apply = getattr(self.world, "apply_symbolic", None)
                if (added or deleted) and apply is not None:
                    apply(add=sorted(deleted), delete=sorted(added))
                    symbolic = getattr(self.world, "symbolic_state", None)
                    if symbolic is not None:
                        run.state = symbolic()
                    if anchored is not None:
                        anchored[0].difference_update(added)
                        anchored[1].difference_update(deleted)
                    run.problem = dataclasses.replace(planned, goal=list(getattr(run.problem, "goal", None) or []))
                    how += " (the refinements' perceived facts taken back)"
        if fallback is None:
            state = run.state
            fresh = dataclasses.replace(self.problem, state=state, init=sorted(state))
            result = plan(self.base_domain, fresh, external=external, max_seconds=budget)
            if result.status == "success" and result.tree is not None:
                done = [(str(s[0]), tuple(str(a) for a in s[1:])) for s in learned[:failed]]
                fallback = PlanState(result.tree, 0, done, rebound=dict(plan_state.rebound))
                how = f"the hand-written methods planned from where the world is now ({len(result.plan)} step(s))"
        report.fallback = {"refinements": list(report.refinements_used), "step": failed, "reason": reason,
                           "to": how if fallback is not None else None}
        if fallback is None:
            report.fallback["to"] = None
            report.fallback["why_not"] = ("the hand-written methods plan nothing from where the world is now: the "
                                          "learned plan is repaired as it stands")
        log.info("meta: learned refinement(s) %s demoted (%s); fallback: %s", report.refinements_used, reason,
                 report.fallback.get("to") or report.fallback.get("why_not"))
        run.emit("repair", outcome="fallback", fallback=dict(report.fallback),
                 reason=f"learned plan demoted ({reason}); going on with "
                        f"{report.fallback.get('to') or 'it as it stands'}")
        return fallback

    def _note_replay(self, method: str, *, succeeded: bool, reason: str | None = None) -> None:
        note = getattr(self.refinements, "note_replay", None)
        if note is not None:
            note(method, succeeded=succeeded, reason=reason)

    def _weakens(self, proposal: Any, before: PlanState, after: PlanState, failed_step: int, domain: Any,
                 base_goal: list[Any], origin_plan: list[list[str]], start_state: Any,
                 anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]], undone: list[tuple[str, ...]],
                 touched: list[dict[str, Any]]) -> str | None:
        """Why applying ``proposal`` would change what counts as done (``None``: it does not): a verification step
        still to pass would not run as it is, or the goal as the repair rewrites it drops a fact of ``base_goal``
        that no entity the repairs perceived, substituted or rebound accounts for."""
        # where the new plan resumes, in the old plan's steps (a backtrack resumes earlier, a replan from scratch
        # commits the steps run): every verification step of the old plan from there must run as it is
        resume = len(after.committed) + after.cursor - len(before.committed)
        needed = verification_calls(self.world, before, max(0, min(failed_step, resume)))
        remaining = [tuple(str(a) for a in n.task) for n in after.steps()[after.cursor:]]
        missing = missing_verifications(needed, remaining)
        if missing:
            return ("it would rewrite, skip or drop the verification step(s) "
                    + ", ".join(atom_text(c) for c in missing))
        if not base_goal or (getattr(proposal, "evidence", None) or {}).get("keep_goal"):
            return None
        add, delete = proposal_facts(getattr(proposal, "changes", None) or {})
        facts = (anchored[0] | set(add), anchored[1] | set(delete))
        goal = self._rewritten_goal(domain, base_goal, origin_plan, [[a, *args] for a, args in after.full_plan()],
                                    start_state, facts, _still_undone(domain, [*undone, *delete], after))
        mappings = [*touched, _mapping_of(proposal.to_dict() if hasattr(proposal, "to_dict") else {})]
        weak = weakened_goal(base_goal, goal, touched_entities([*facts[0], *facts[1]], mappings))
        if weak:
            return "it would weaken the goal: " + ", ".join(atom_text(g) for g in weak) + " no longer reached"
        return None

    def _finish(self, report: RunReport, run: RunContext, wall_started: float) -> RunReport:
        report.failures = [f.to_dict() for f in run.failures]
        report.seconds = time.perf_counter() - wall_started
        run.emit("run_end", status=report.status, ticks=report.ticks)
        log.info("meta: run %s %s after %d attempt(s) in %.3f s%s", report.problem, report.status,
                 len(report.attempts), report.seconds, f" ({report.stop_reason})" if report.stop_reason else "")
        return report


def _apply_facts(world: Any, proposal: Any, anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]],
                 undone: list[tuple[str, ...]]) -> bool:
    """Make a proposal's ``changes["facts"]`` (``{"add": [atom, ...], "delete": [...]}``) true in the world's
    symbolic state (``world.apply_symbolic``) as it is applied -- not when it is proposed, since a proposal that is
    never applied must leave the belief alone (a re-tiling takes placed blocks back off the drawing) -- and note
    them with the anchored facts, and the deleted ones in ``undone``. Whether anything changed."""
    add, delete = proposal_facts(getattr(proposal, "changes", None) or {})  # checked when it was applied
    apply = getattr(world, "apply_symbolic", None)
    if apply is None or not (add or delete):
        return False
    before = _symbolic(world)
    apply(add=add, delete=delete)
    _note_changes(anchored, before, _symbolic(world))
    undone[:] = [f for f in undone if f not in add] + [f for f in delete if f not in undone]
    return True


def _still_undone(domain: Any, undone: list[tuple[str, ...]], plan_state: PlanState) -> list[tuple[str, ...]]:
    """The facts repairs made false (``undone``) that no step still to run makes true again."""
    if not undone:
        return []
    again: set[tuple[str, ...]] = set()
    for node in plan_state.steps()[plan_state.cursor:]:
        primitive = domain.primitives.get(str(node.task[0]))
        if primitive is None:
            continue
        try:
            added, _ = primitive.effects(primitive.ground([str(a) for a in node.task[1:]]).bindings)
        except (BtMetaError, KeyError, TypeError, ValueError):  # effects that need the state: none known
            continue
        again |= {tuple(str(a) for a in f) for f in added}
    return [f for f in undone if f not in again]


def _robot_name(world: Any) -> str | None:
    """The name of the robot ``world`` runs (``world.robot_name``, or its simulation's robot), ``None`` unknown."""
    name = getattr(world, "robot_name", None)
    if name is None:
        name = getattr(getattr(getattr(world, "sim", None), "robot", None), "name", None)
    return None if name is None else str(name)


def _monitor_signature(failure: Failure) -> list[list[Any]] | None:
    """What a monitor objected to (each mismatch's kind, plugin and failed relations), ``None`` for a failure no
    monitor raised (a skill's, a verification)."""
    mismatches = (failure.evidence or {}).get("mismatches")
    if not mismatches:
        return None
    return sorted([str(m.get("kind")), str(m.get("plugin")), sorted(str(x) for x in (m.get("evidence") or {})
                                                                   .get("failed") or [])] for m in mismatches)


def _passed_through(attempts: list[Attempt], plan: list[list[str]]) -> list[dict[str, Any]]:
    """The monitor objections of ``attempts`` that a refinement replaying ``plan`` will meet again: the failed step
    is in ``plan`` at the same place, kept as it ran, because its attempt's plugin keeps a plan that replays the
    moves this run made before the repair (``evidence["replay_plan"]``)."""
    out = []
    for attempt in attempts:
        failure = attempt.failure
        monitor = failure.get("monitor")
        step = failure.get("step")
        if not monitor or step is None or not (attempt.proposal.get("evidence") or {}).get("replay_plan"):
            continue
        call = [str(failure.get("action")), *(str(a) for a in failure.get("args") or [])]
        if 0 <= int(step) < len(plan) and [str(a) for a in plan[int(step)]] == call:
            out.append({"step": int(step), "kind": failure.get("kind"), "call": call, "monitor": monitor})
    return out


def _expected_by(failures: list[Failure], plan_state: PlanState, expected: list[dict[str, Any]]
                 ) -> dict[str, Any] | None:
    """The entry of ``expected`` (taken out of it) that the segment's failure is: the same monitor objection at the
    same step of the same plan, with the step's call as it was; ``None`` when it is anything else."""
    located = [f for f in failures if f.step is not None]
    if not located or not expected:
        return None
    failure = located[-1]
    signature = _monitor_signature(failure)
    steps = plan_state.steps()
    if signature is None or not 0 <= failure.step < len(steps) or len(plan_state.committed):
        return None
    call = [str(a) for a in steps[failure.step].task]
    for index, entry in enumerate(expected):
        if (int(entry.get("step", -1)) == failure.step and entry.get("kind") == failure.kind.value
                and [str(a) for a in entry.get("call") or []] == call and entry.get("monitor") == signature):
            del expected[index]
            return {**entry, "message": failure.message}
    return None


def _rearranged(before: PlanState, after: PlanState, perceived: set[str]) -> set[str]:
    """The perceived objects named by steps ``after`` runs differently from ``before`` (from where either resumes)."""
    def calls(state: PlanState) -> list[tuple[str, ...]]:
        return [tuple(str(a) for a in n.task) for n in state.steps()[state.cursor:]]

    return _rearranged_calls(calls(before), calls(after), perceived)


def _rearranged_calls(before: Iterable[tuple[str, ...]], after: Iterable[tuple[str, ...]],
                      perceived: set[str]) -> set[str]:
    """The perceived objects named by calls that ``after`` has and ``before`` has not, or the other way round."""
    old, new = Counter(before), Counter(after)
    changed = (old - new) + (new - old)
    return {str(a) for call in changed for a in call[1:] if str(a) in perceived}


def _call_of(text: str) -> tuple[str, ...]:
    """``place(b1, 0, 0)`` -> ``("place", "b1", "0", "0")`` (a refinement's subtask, as :func:`atom_text` wrote it)."""
    name, _, rest = text.strip().partition("(")
    args = rest.rstrip().removesuffix(")")
    return (name.strip(), *(a.strip() for a in args.split(",") if a.strip()))


def _mapping_of(proposal: dict[str, Any]) -> dict[str, Any]:
    """The objects a proposal renames or rebinds (``substitute``'s mapping, ``rebind``'s symbols)."""
    changes = proposal.get("changes") or {}
    out: dict[str, Any] = {}
    for key in ("mapping", "symbols"):
        value = changes.get(key)
        if isinstance(value, dict):
            out.update({str(k): str(v) for k, v in value.items()})
    return out


def _rebind(world: Any, before: dict[str, str], after: dict[str, str]) -> None:
    """Tell the world the grounding symbols ``after`` binds differently from ``before`` (``rebind_object``)."""
    rebind = getattr(world, "rebind_object", None)
    for symbol, name in after.items():
        if before.get(symbol) != name and rebind is not None:
            rebind(symbol, name)


def _with_tried(entry: dict[str, Any], attempts: list[Attempt], diagnosis: Diagnosis,
                dropped: list[dict[str, Any]], skipped: list[dict[str, Any]]) -> dict[str, Any]:
    """``entry`` (an unrepaired failure of the run report) with ``tried``: every applied attempt and how it ended
    (the failure that followed it), then the proposals for this failure that were dropped or not applied, and why."""
    tried: list[dict[str, Any]] = []
    for index, attempt in enumerate(attempts):
        after = attempts[index + 1].failure if index + 1 < len(attempts) else diagnosis.failure.to_dict()
        tried.append({"attempt": attempt.number, "action": attempt.proposal.get("action"),
                      "plugin": attempt.proposal.get("plugin"), "description": attempt.proposal.get("description"),
                      "change": attempt.change, "outcome": attempt.outcome,
                      "why": f"then failed: [{after.get('kind')}] step {after.get('step')} {after.get('action')}"
                             f"({', '.join(map(str, after.get('args') or []))}): {after.get('message')}"})
    for item in [*dropped, *skipped]:
        proposal = item.get("proposal")
        proposal = proposal if isinstance(proposal, dict) else {"action": str(proposal)}
        tried.append({"attempt": None, "action": proposal.get("action"), "plugin": proposal.get("plugin")
                      or item.get("plugin"), "description": proposal.get("description"), "outcome": "not_applied",
                      "why": item.get("reason")})
    entry["tried"] = tried
    return entry


def _unapplied_reason(diagnosis: Diagnosis, skipped: list[dict[str, Any]]) -> str:
    """Why no proposal for ``diagnosis`` was applied: each one's reason; repeats of earlier attempts named."""
    where = f"{diagnosis.kind.value} at step {diagnosis.step}"
    each = "; ".join(f"{s['proposal']['action']} ({s['proposal'].get('plugin')}): {s['reason']}" for s in skipped)
    equivalent = sorted({s["equivalent_to"] for s in skipped if "equivalent_to" in s})
    if equivalent and all("equivalent_to" in s for s in skipped):
        head = (f"every proposal for {where} would repeat an attempt already made (attempt(s) "
                f"{', '.join(map(str, equivalent))}): not looped on")
    elif equivalent:
        head = (f"no proposal for {where} could be applied, or it would repeat attempt(s) "
                f"{', '.join(map(str, equivalent))}: not looped on")
    else:
        head = f"no proposal for {where} could be applied"
    return f"{head} -- {each}" if each else head


def _failed_step(failures: list[Failure], plan_state: PlanState) -> int:
    """The step a segment stopped at: the last failure's step, or the first step below a failed guard's node."""
    for failure in reversed(failures):
        if failure.step is not None:
            return failure.step
        if failure.node_id in plan_state.tree.nodes:
            below = [n.step for n in plan_state.tree.primitives(failure.node_id) if n.step is not None]
            if below:
                return min(below)
    return plan_state.cursor


def _symbolic(world: Any) -> set[tuple[str, ...]]:
    symbolic = getattr(world, "symbolic_state", None)
    return set() if symbolic is None else {tuple(a) for a in symbolic()}


def _note_changes(anchored: tuple[set[tuple[str, ...]], set[tuple[str, ...]]], before: set[tuple[str, ...]],
                  after: set[tuple[str, ...]]) -> None:
    """Accumulate the facts added and deleted between ``before`` and ``after`` (a later change undoes an
    earlier one)."""
    added, deleted = anchored
    for fact in after - before:
        deleted.discard(fact)
        added.add(fact)
    for fact in before - after:
        added.discard(fact)
        deleted.add(fact)


def _objects(world: Any) -> dict[str, Any]:
    observe = getattr(world, "observe", None)
    if observe is None:
        return {}
    try:
        objects = observe().get("objects") or {}
    except Exception as error:  # a world that cannot observe still runs; refinements then carry no poses
        log.info("meta: the world's objects could not be observed: %s", error)
        return {}
    return dict(objects)


def _world_names(world: Any, problem: Any) -> dict[str, str]:
    """Task-file object symbol -> the world's name for it, where the world says they differ (``object_name``)."""
    to_world = getattr(world, "object_name", None)
    objects = getattr(problem, "objects", None) or {}
    if to_world is None or not isinstance(objects, dict):
        return {}
    names = {}
    for group in objects.values():
        for symbol in group:
            try:
                name = str(to_world(symbol))
            except Exception:  # a symbol the world does not ground as an object (a pose, a feature)
                continue
            if name != symbol:
                names[str(symbol)] = name
    return names


def _declare_symbols(world: Any, domain: Any, added: list[str], problem: Any) -> Any:
    """Durable symbols in the learned refinements (a repair's sampled pose, ``pose:x:y:z:r:p:y``) made known to
    the world (``world.register_pose``), and ``problem`` with the type facts the world then reports: the planner
    checks a refinement's argument types in the problem's state, the run's belief starts from the world's."""
    register = getattr(world, "register_pose", None)
    if register is None or not added:
        return problem
    symbols = sorted({str(arg) for method in domain.methods if method.name in added
                      for subtask in method.subtasks for arg in subtask[1:] if not str(arg).startswith("?")})
    declared = {symbol for symbol in symbols if register(symbol)}
    if not declared:
        return problem
    facts = [atom for atom in world.symbolic_state() if any(str(arg) in declared for arg in atom[1:])]
    state = problem.state.apply(add=facts)
    return dataclasses.replace(problem, init=[*problem.init, *(f for f in facts if f not in problem.state)],
                               state=state)


def run_task_file(
    path: str | Path,
    problem: str | None = None,
    *,
    plugins: Any = None,
    world: Any = "fake",
    faults: Iterable[Any] = (),
    **options: Any,
) -> RunReport:
    """Load ``path``, make the world (``"fake"`` with scripted ``faults``, another plugin's world by name, or a
    World object) and run ``problem`` with repairs; ``options`` go to :class:`MetaExecutor`."""
    from bt_meta.htn import load_task_file
    from bt_meta.plugins import create_plugin_host

    task_file = load_task_file(path)
    chosen = task_file.problem(problem)
    if plugins is None:
        plugins = create_plugin_host(project_file=path)
    if isinstance(world, str):
        made = plugins.call("bt_meta_make_world", name=world, domain=task_file.domain, problem=chosen,
                            options={"faults": list(faults)})
        if made.errors:
            error = made.errors[0]
            if isinstance(error.error, BtMetaError) and not isinstance(error.error, PluginError):
                raise error.error  # e.g. the simulator's located error in a scene file
            raise PluginError(error.message) from error.error
        if not made.results:
            raise UnknownWorldError(f"no plugin provides a world named {world!r} (shipped: fake, sim)")
        world = made.first
    return MetaExecutor(task_file.domain, chosen, world, plugins, task_file=task_file, **options).run()
