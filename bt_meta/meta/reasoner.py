"""The meta-reasoner: from the failures of one execution segment to the repair to apply (sections 3, 6.4, 7.4).

On a monitor failure or a failed verification the reasoner

1. *gathers* the segment's failures and picks the primary one (the failing step's), the rest kept as related;
2. *localises* it: the plan step, the decomposition node, its ancestors (task, method) -- written into the
   failure's evidence (``localisation``, ``plan``, ``repair_history``) so repair plugins can use them;
3. *classifies* it with the firstresult hook ``bt_meta_classify_failure`` (the shipped rules are the plugin
   ``bt_meta_plugins.classification_rules``), with the mismatches rebuilt from the monitor's evidence;
4. *asks* every ``bt_meta_propose_repairs`` implementation for :class:`RepairProposal` s, contains plugin errors
   (recorded as ``internal`` failures), drops unknown kinds, proposals already tried for this failure, and any
   ``retry`` of a collision or reachability failure, and ranks the rest by score. A plugin may also answer with a
   collision or reachability :class:`Failure` instead of a proposal: the repair it knows is needed (a pose from
   experience) is blocked by that motion limit, which it checked (IK, collision) without moving the robot. Then
   the blind proposals (retry, replan, replan from scratch: they would re-run the same motions) are dropped;
5. *decides*: stop when the attempt or time budget is spent, when a motion limit (collision, reachability)
   recurs at a step already repaired once, or when nothing is proposed -- with the limits plugins reported
   (:attr:`Decision.limits`), which the run report lists with their evidence; otherwise hand the ranked
   proposals to the executor, which applies the first that applies.

Every decision is logged (``bt_meta.meta``) and sent as a ``"repair"`` trace event.

Offers:

* :class:`MetaReasoner` -- :meth:`~MetaReasoner.diagnose`, :meth:`~MetaReasoner.propose`, :meth:`~MetaReasoner.decide`
* :class:`Limits` -- attempt and wall-time budgets
* :class:`Diagnosis` -- a localised, classified failure with its related failures
* :class:`Decision` -- ranked proposals to try, or why the reasoner stops
* :class:`Attempt` -- one applied repair and its outcome (what the run report lists)
* :class:`ReasonerPlugin` -- ``bt_meta_on_failure`` advice (kind and ranked proposals as notes) for runs without
  the executor, e.g. ``bt-meta tick``
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import asdict, dataclass, field
from typing import Any

from bt_meta.bt.expectations import Comparison, Expectation, StepContext
from bt_meta.bt.failures import Failure, FailureKind, RepairProposal, parse_kind
from bt_meta.errors import BtMetaError
from bt_meta.meta.proposals import PROPOSAL_KINDS, REPLAN, REPLAN_SCRATCH, RETRY, PlanState, proposal_key
from bt_meta.meta.taxonomy import MOTION_LIMITS, motion_evidence
from bt_meta.plugins import hookimpl

__all__ = ["Attempt", "Decision", "Diagnosis", "Limits", "MetaReasoner", "ReasonerPlugin"]

log = logging.getLogger("bt_meta.meta")

CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
"""What a :class:`Limits` time budget can count."""

BLIND = frozenset({RETRY, REPLAN, REPLAN_SCRATCH})
"""Proposals that re-run the plan's own motions: useless against a motion limit a plugin found."""


@dataclass
class Limits:
    """Budgets of one repaired run: applied repairs, time (planning and replanning included), ticks.

    ``clock`` says what the time budget counts: ``"wall"`` (the default: what an operator waits) or ``"cpu"`` (this
    process's CPU time, which a loaded machine does not eat; campaigns use it so an episode's outcome does not depend
    on how many other episodes share the cores).
    """

    max_attempts: int = 5
    max_seconds: float = 60.0
    max_ticks: int = 100_000
    clock: str = "wall"

    def __post_init__(self) -> None:
        if self.max_attempts < 0 or self.max_seconds <= 0 or self.max_ticks <= 0:
            raise BtMetaError(f"bad repair limits: {self}; attempts >= 0, seconds > 0 and ticks > 0 required")
        if self.clock not in CLOCKS:
            raise BtMetaError(f"bad repair limits: clock {self.clock!r}; one of {', '.join(sorted(CLOCKS))}")

    def now(self) -> float:
        """The budget clock's reading, in seconds (only differences mean anything)."""
        return CLOCKS[self.clock]()


@dataclass
class Diagnosis:
    """A failure localised in the plan and classified."""

    failure: Failure
    step: int
    node_id: str | None
    kind: FailureKind
    related: list[Failure] = field(default_factory=list)
    classified_by: str | None = None
    ancestors: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"failure": self.failure.to_dict(), "step": self.step, "node_id": self.node_id,
                "kind": self.kind.value, "classified_by": self.classified_by, "ancestors": self.ancestors,
                "related": [f.summary() for f in self.related]}


@dataclass
class Decision:
    """What to do about a diagnosis: ``proposals`` to try in order, or ``stop`` with a ``reason``."""

    proposals: list[RepairProposal]
    stop: bool = False
    reason: str = ""
    dropped: list[dict[str, Any]] = field(default_factory=list)
    limits: list[Failure] = field(default_factory=list)
    """Collision or reachability failures plugins found blocking the repair they would propose (never applied:
    reported with their evidence)."""


@dataclass
class Attempt:
    """One applied repair: the failure it answered, the proposal, the change, and how the next segment went."""

    number: int
    failure: dict[str, Any]
    kind: str
    proposal: dict[str, Any]
    change: str
    step: int
    seconds: float
    outcome: str = "pending"
    """``"repaired"`` (the rest of the run succeeded), ``"failed_again"`` or ``"not_applicable"``."""
    replaced: list[list[str]] = field(default_factory=list)
    """The plan's steps the attempt changed, as they were (a splice's replaced steps, the steps a backtrack or a
    rewrite gives new arguments, the step a substitution renames from): a later refinement finds them again in a
    plan replayed from the start."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class MetaReasoner:
    """Diagnoses failures and ranks repairs through the plugin host ``plugins`` within ``limits``."""

    def __init__(self, plugins: Any, limits: Limits | None = None) -> None:
        self.plugins = plugins
        self.limits = limits or Limits()

    # -- 1-3: gather, localise, classify -------------------------------------------------------------------------

    def diagnose(self, failures: list[Failure], plan_state: PlanState, run: Any,
                 history: list[Attempt] | None = None) -> Diagnosis:
        """Pick the primary failure of a segment, localise it in ``plan_state`` and classify it."""
        if not failures:
            raise BtMetaError("diagnose() needs at least one failure")
        located = [f for f in failures if f.step is not None or f.node_id is not None]
        primary = located[-1] if located else failures[-1]
        related = [f for f in failures if f is not primary]
        tree = plan_state.tree
        step = primary.step
        node_id = primary.node_id
        if step is None and node_id in tree.nodes:  # a guard of a compound node: its first step
            below = [n.step for n in tree.primitives(node_id) if n.step is not None]
            step = min(below) if below else None
        if step is None:
            step = plan_state.cursor
        if node_id is None or node_id not in tree.nodes:
            node = next((n for n in tree.primitives() if n.step == step), None)
            node_id = None if node is None else node.id
        ancestors = [] if node_id is None else [
            {"id": a.id, "task": list(a.task), "method": a.method} for a in tree.ancestors(node_id)]
        primary.evidence["localisation"] = {"step": step, "node_id": node_id, "ancestors": ancestors}
        # The segment started at the cursor and ran up to the failing step: the steps before it are done.
        executed = plan_state if step < plan_state.cursor else dataclasses.replace(plan_state, cursor=step)
        primary.evidence["plan"] = executed.describe()
        primary.evidence["methods"] = _methods(plan_state)
        primary.evidence["repair_history"] = [a.to_dict() for a in history or []]
        if related:
            primary.evidence.setdefault("related", [f.summary() for f in related])
        kind, by = self._classify(primary, run, step, node_id, plan_state)
        return Diagnosis(primary, step, node_id, kind, related, by, ancestors)

    def _classify(self, failure: Failure, run: Any, step: int, node_id: str | None,
                  plan_state: PlanState) -> tuple[FailureKind, str | None]:
        if not self.plugins.implements("bt_meta_classify_failure"):
            return failure.kind, failure.evidence.get("classified_by")
        mismatches = [_comparison(record) for record in failure.evidence.get("mismatches", [])]
        context = self.context_of(failure, run, step, node_id, plan_state)
        result = self.plugins.call("bt_meta_classify_failure", failure=failure, mismatches=mismatches,
                                   context=context)
        if result.errors and run is not None:
            run.contain(result, context)
        if result.results:
            try:
                kind = parse_kind(result.first)
            except BtMetaError as error:
                failure.evidence["classification_error"] = f"plugin {result.first_plugin!r}: {error}"
            else:
                if kind != failure.kind:
                    failure.evidence["suggested_kind"] = failure.kind.value
                failure.kind = kind
                failure.evidence["classified_by"] = result.first_plugin
                return kind, result.first_plugin
        return failure.kind, failure.evidence.get("classified_by")

    @staticmethod
    def context_of(failure: Failure, run: Any, step: int, node_id: str | None,
                   plan_state: PlanState) -> StepContext:
        """A step context for the failed step, as repair plugins receive it."""
        node = plan_state.tree.nodes.get(node_id) if node_id else None
        action = failure.action or (node.task[0] if node is not None else "")
        args = tuple(failure.args) or (tuple(node.task[1:]) if node is not None else ())
        domain = None if run is None else run.domain
        primitive = None if domain is None else domain.primitives.get(action)
        bindings = {} if primitive is None else dict(zip(primitive.parameters, args, strict=False))
        return StepContext(action=action, args=args, node_id=node_id, step=step, node_name=failure.node_name,
                           primitive=primitive, bindings=bindings,
                           state_before=None if run is None else run.state, run=run)

    # -- 4: proposals --------------------------------------------------------------------------------------------

    def propose(self, diagnosis: Diagnosis, run: Any, plan_state: PlanState,
                tried: set[str]) -> tuple[list[RepairProposal], list[dict[str, Any]]]:
        """Every plugin's proposals, filtered and ranked (best first); also what was dropped and why."""
        proposals, dropped, _ = self.propose_with_limits(diagnosis, run, plan_state, tried)
        return proposals, dropped

    def propose_with_limits(self, diagnosis: Diagnosis, run: Any, plan_state: PlanState, tried: set[str]
                            ) -> tuple[list[RepairProposal], list[dict[str, Any]], list[Failure]]:
        """:meth:`propose`, plus the motion limits plugins reported instead of a proposal (see the module
        docstring); with a limit, blind proposals (retry, replan, replan from scratch) are dropped."""
        context = self.context_of(diagnosis.failure, run, diagnosis.step, diagnosis.node_id, plan_state)
        result = self.plugins.call("bt_meta_propose_repairs", failure=diagnosis.failure, context=context)
        if result.errors and run is not None:
            run.contain(result, context)
        ranked: list[tuple[float, int, RepairProposal]] = []
        dropped: list[dict[str, Any]] = []
        limits: list[Failure] = []
        order = 0
        for plugin, value in result.results:
            items = value if isinstance(value, (list, tuple)) else [value]
            for item in items:
                reason = None
                if isinstance(item, Failure) and item.kind in MOTION_LIMITS:
                    item.evidence.setdefault("plugin", plugin)
                    limits.append(item)
                    continue
                if not isinstance(item, RepairProposal):
                    reason = f"not a RepairProposal: {type(item).__name__}"
                else:
                    item.plugin = item.plugin or plugin
                    if item.action not in PROPOSAL_KINDS:
                        reason = f"unknown kind {item.action!r}"
                    elif item.action == RETRY and diagnosis.kind in MOTION_LIMITS:
                        reason = f"a retry of a {diagnosis.kind.value} failure would fail the same way"
                    elif self._key(item, diagnosis) in tried:
                        reason = "already tried for this failure"
                    else:
                        try:
                            score = float(item.score)
                        except (TypeError, ValueError):
                            reason = f"score {item.score!r} is not a number"
                        else:
                            ranked.append((-score, order, item))
                            order += 1
                            continue
                dropped.append({"plugin": plugin, "proposal": repr(item) if not isinstance(item, RepairProposal)
                                else item.to_dict(), "reason": reason})
        ranked.sort(key=lambda entry: (entry[0], entry[1]))
        proposals = [entry[2] for entry in ranked]
        if limits:
            blind = [p for p in proposals if p.action in BLIND]
            proposals = [p for p in proposals if p.action not in BLIND]
            why = ", ".join(f"{f.kind.value} ({f.evidence.get('plugin')})" for f in limits)
            dropped.extend({"plugin": p.plugin, "proposal": p.to_dict(),
                            "reason": f"the repair experience asks for is blocked by a motion limit: {why}; "
                                      f"a {p.action} would run the same motions again"} for p in blind)
        return proposals, dropped, limits

    @staticmethod
    def _key(proposal: RepairProposal, diagnosis: Diagnosis) -> str:
        return f"{diagnosis.kind.value}@{diagnosis.step}:{proposal_key(proposal)}"

    def key(self, proposal: RepairProposal, diagnosis: Diagnosis) -> str:
        """The de-duplication key of ``proposal`` for this failure (kind and step included)."""
        return self._key(proposal, diagnosis)

    # -- 5: decide -----------------------------------------------------------------------------------------------

    def decide(self, diagnosis: Diagnosis, run: Any, plan_state: PlanState, history: list[Attempt],
               tried: set[str], started: float) -> Decision:
        """Ranked proposals to try, or a stop with its reason (budgets, a recurring motion limit, nothing left)."""
        if len(history) >= self.limits.max_attempts:
            return self._stop(diagnosis, f"attempt budget spent ({self.limits.max_attempts} repair attempt(s))")
        elapsed = self.limits.now() - started
        if elapsed >= self.limits.max_seconds:
            return self._stop(diagnosis, f"time budget spent ({elapsed:.2f} s of {self.limits.max_seconds} s "
                                         f"{self.limits.clock} time)")
        # The same motion limit at the same step again: the repair did not change what limits it -- unless the
        # failure names an object out of reach that no earlier failure did (a stand-in found out of reach in
        # turn: a new failure, answered as one; the objects are finite and none is offered twice).
        if diagnosis.kind in MOTION_LIMITS and not _newly_out_of_reach(diagnosis.failure, run) and any(
                a.kind == diagnosis.kind.value and a.step == diagnosis.step for a in history):
            return self._stop(diagnosis, f"{diagnosis.kind.value} again at step {diagnosis.step} after a repair: "
                                         "a motion limit is reported, never looped on")
        proposals, dropped, limits = self.propose_with_limits(diagnosis, run, plan_state, tried)
        if not proposals and limits:
            first = limits[0]
            decision = self._stop(diagnosis, f"{first.kind.value} blocks the repair of {diagnosis.kind.value} at step "
                                             f"{diagnosis.step} ({first.message}): reported with its evidence, not "
                                             "looped on")
            decision.dropped, decision.limits = dropped, limits
            return decision
        if not proposals:
            if diagnosis.kind in MOTION_LIMITS:
                reason = (f"{diagnosis.kind.value} at step {diagnosis.step}: reported with its evidence, not "
                          "repaired (no plugin proposed a different motion)")
            else:
                reason = f"no repair proposed for {diagnosis.kind.value} at step {diagnosis.step}"
            decision = self._stop(diagnosis, reason)
            decision.dropped = dropped
            return decision
        log.info("meta: %s -> %d proposal(s): %s", diagnosis.failure.summary(), len(proposals),
                 ", ".join(f"{p.action} {p.score:.2f} ({p.plugin})" for p in proposals))
        return Decision(proposals, dropped=dropped)

    @staticmethod
    def _stop(diagnosis: Diagnosis, reason: str) -> Decision:
        log.info("meta: stop after %s: %s", diagnosis.failure.summary(), reason)
        return Decision([], stop=True, reason=reason)

    @staticmethod
    def limit_entry(limit: Failure, diagnosis: Diagnosis) -> dict[str, Any]:
        """What a run report lists for a motion limit a plugin found blocking the repair of ``diagnosis``."""
        return {"kind": limit.kind.value, "step": limit.step if limit.step is not None else diagnosis.step,
                "node_id": limit.node_id, "action": limit.action, "args": list(limit.args), "message": limit.message,
                "evidence": motion_evidence(limit.evidence), "plugin": limit.evidence.get("plugin"),
                "blocks_repair_of": {"kind": diagnosis.kind.value, "step": diagnosis.step}}

    @staticmethod
    def report_entry(diagnosis: Diagnosis) -> dict[str, Any]:
        """What a run report lists for an unrepaired failure; motion limits carry their evidence."""
        entry = {"kind": diagnosis.kind.value, "step": diagnosis.step, "node_id": diagnosis.node_id,
                 "action": diagnosis.failure.action, "args": list(diagnosis.failure.args),
                 "message": diagnosis.failure.message}
        if diagnosis.kind in MOTION_LIMITS:
            entry["evidence"] = motion_evidence(diagnosis.failure.evidence)
        return entry


def _methods(plan_state: PlanState) -> list[dict[str, Any]]:
    """Each compound node with a step still to run: its task, method, bindings and steps -- what a repair plugin
    needs to tell which of a method's conditions an entity it would replace must meet (its colour, its shape)."""
    tree = plan_state.tree
    out = []
    for node in tree.walk():
        if node.kind != "compound" or node.method is None:
            continue
        steps = sorted(p.step for p in tree.primitives(node.id) if p.step is not None)
        if steps and steps[-1] >= plan_state.cursor:
            out.append({"node_id": node.id, "task": list(node.task), "method": node.method,
                        "bindings": {str(k): str(v) for k, v in node.bindings.items()}, "steps": steps})
    return out


def _comparison(record: dict[str, Any]) -> Comparison:
    """A monitor mismatch record (``evidence["mismatches"]``) back as a :class:`Comparison`."""
    expectation = Expectation(kind=str(record.get("kind") or ""), description=str(record.get("expectation") or ""),
                              plugin=record.get("plugin"))
    return Comparison(matched=False, message=str(record.get("message") or ""),
                      evidence=dict(record.get("evidence") or {}), expectation=expectation,
                      plugin=record.get("plugin"))


class ReasonerPlugin:
    """``bt_meta_on_failure`` advice for runs the executor does not drive: classify and rank, apply nothing.

    Register an instance (``host.register(ReasonerPlugin(host), "meta_advice")``); each failure's notes get
    ``kind``, ``classified_by`` and the ranked ``proposals``. Failures without a step (guards, plugins) get none.
    """

    def __init__(self, plugins: Any, limits: Limits | None = None) -> None:
        self.reasoner = MetaReasoner(plugins, limits)

    @hookimpl
    def bt_meta_on_failure(self, failure: Failure, context: StepContext | None) -> dict[str, Any] | None:
        if failure.step is None or context is None or failure.kind is FailureKind.INTERNAL:
            return None
        from bt_meta.htn.state import State
        from bt_meta.htn.tree import DecompositionNode, DecompositionTree

        node_id = failure.node_id or f"s{failure.step}"
        node = DecompositionNode(node_id, (failure.action or context.action, *failure.args), "primitive", None,
                                 dict(context.bindings), None, State(), failure.step, [])
        plan_state = PlanState(DecompositionTree({node_id: node}, [node_id]), failure.step)
        diagnosis = Diagnosis(failure, failure.step, node_id, failure.kind)
        proposals, _ = self.reasoner.propose(diagnosis, context.run, plan_state, set())
        return {"kind": failure.kind.value, "proposals": [p.to_dict() for p in proposals]}


def _newly_out_of_reach(failure: Failure, run: Any) -> bool:
    """Whether ``failure`` names an object ``out_of_reach`` that no earlier failure of ``run`` named."""
    name = (failure.evidence or {}).get("out_of_reach")
    if not name:
        return False
    earlier = [f for f in getattr(run, "failures", None) or [] if f is not failure]
    return all((f.evidence or {}).get("out_of_reach") != name for f in earlier)
