"""The Monitor decorator: checks a primitive's preconditions, then compares what happened with what should have.

Every primitive of a compiled or loaded tree runs inside a Monitor (section 3 of the paper). Before its child
starts, the monitor checks the primitive's precondition against the run's belief state (kind ``precondition``
on failure; the child is not started; before the run's first step starts it also keeps what the observe plugins
report then, ``RunContext.start_observations``). When the child succeeds it gathers observations (``bt_meta_observe``,
with an :class:`~bt_meta.bt.expectations.ObserveRequest` of the keys the readers declared through
``bt_meta_observation_needs``, so a camera frame nobody reads is not rendered; after a failed step only the belief),
asks for expectations (``bt_meta_expectations``) and compares each (``bt_meta_compare``); a mismatch turns
SUCCESS into FAILURE with a structured :class:`~bt_meta.bt.failures.Failure` on ``/bt_meta/failures`` and in the
run log, after which the meta-reasoner hook runs. A failing child's own failure (its skill's kind) is recorded the
same way. A plugin that raises fails the node with kind ``internal``; the tree keeps ticking.

Fast path: while the child is RUNNING the monitor only relays the tick; the bound precondition and ground effects
are computed once when the arguments are literals; hooks nobody implements are not called; a plain leaf child is
ticked through its ``initialise``/``update``/``terminate`` directly (py_trees' leaf protocol, without its per-tick
debug formatting), and still yielded so visitors see it.

Offers:

* :class:`Monitor` -- the decorator (``is_monitor = True`` so the XML writer writes only its child)
* :func:`monitor_action` -- the ``wrap_action`` callable the XML loader takes
"""

from __future__ import annotations

import logging
import re
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.actions import PrimitiveAction
from bt_meta.bt.context import RunContext, current_run
from bt_meta.bt.expectations import OBSERVE_ALL, Comparison, Expectation, ObserveRequest, StepContext
from bt_meta.bt.failures import Failure, FailureKind, parse_kind
from bt_meta.errors import BtMetaError
from bt_meta.htn.state import atom_text

_BEHAVIOUR_TICK = py_trees.behaviour.Behaviour.tick
_BEHAVIOUR_STOP = py_trees.behaviour.Behaviour.stop
log = logging.getLogger("bt_meta.monitor")
_RUNNING = Status.RUNNING
BELIEF_ONLY = ObserveRequest(frozenset({"symbolic_state"}))
"""The request of an observation only the monitor's belief update reads (after a failed step)."""
_SUCCESS = Status.SUCCESS
_FAILURE = Status.FAILURE
_PRED_RE = re.compile(r"([A-Za-z_][\w\-]*)\s*\(")
_MAX_STATE_ATOMS = 60


class Monitor(py_trees.decorators.Decorator):
    """Precondition check before, expectation check after, structured failures always.

    ``condition`` / ``bindings`` default to the child's primitive precondition and its parameter bindings (for a
    :class:`~bt_meta.bt.actions.PrimitiveAction`); ``effects`` are the ground ``(add, delete)`` lists the belief
    state takes when no perception plugin supplies a symbolic state.
    """

    is_monitor = True

    def __init__(
        self,
        child: py_trees.behaviour.Behaviour,
        name: str | None = None,
        *,
        condition: Any = None,
        bindings: dict[str, str] | None = None,
        effects: tuple[list[tuple[str, ...]], list[tuple[str, ...]]] | None = None,
        inline_leaf: bool = True,
    ) -> None:
        super().__init__(name=name or f"Monitor<{child.name}>", child=child)
        # A plain leaf (py_trees' own tick() and stop()) is ticked through its initialise/update/terminate
        # directly: the same protocol without py_trees' per-tick debug formatting and generator creation.
        cls = type(child)
        self._inline = (inline_leaf and not child.children and cls.tick is _BEHAVIOUR_TICK
                        and cls.stop is _BEHAVIOUR_STOP)
        self.action = child if isinstance(child, PrimitiveAction) else None
        if self.action is not None:
            self.action.monitored = True
        primitive = self.primitive = None if self.action is None else self.action.primitive
        self._static = self.action is None or self.action._static_args is not None
        self.condition = condition
        if condition is None and primitive is not None:
            self.condition = primitive.precondition
        self.bindings = bindings
        self.effects = effects
        # Effects whose variables are all parameters are ground once; others need the precondition's binding.
        self._effects_need_state = primitive is not None and effects is None and not _effects_use_only_parameters(
            primitive)
        if primitive is not None and self._static:
            args = self.action._static_args or ()  # type: ignore[union-attr]
            if self.bindings is None:
                self.bindings = dict(zip(primitive.parameters, args, strict=False))
            if self.effects is None and not self._effects_need_state:
                self.effects = primitive.effects(self.bindings)
        self._check_types = primitive is not None and any(primitive.types)
        self._check = self.condition is not None and (
            not _trivially_true(self.condition) or self._check_types or self._effects_need_state
            or (primitive is not None and not self._static))
        self._step_effects: tuple[list[tuple[str, ...]], list[tuple[str, ...]]] | None = self.effects
        self.run: RunContext | None = None
        self.context: StepContext | None = None
        self.failure: Failure | None = None

    # -- the tick -----------------------------------------------------------------------------------------------

    def tick(self):  # type: ignore[override]
        if self.status is not _RUNNING:
            self.failure = None
            self.context = None
            run = self.run = current_run()
            self._step_effects = self.effects
            if run is not None and run._trace:
                run.emit("step_start", **self._step_context(run).describe())
            if self._check and run is not None and not self._precondition_holds(run):
                self._finish(_FAILURE)
                yield self
                return
            if run is not None and run.start_observations is None and "bt_meta_observe" in run.hooks \
                    and "bt_meta_compare" in run.hooks:
                context = self._step_context(run)
                run.start_observations = self._observe(run, context, self._request(run, context))[0]
        child = self.decorated
        if self._inline:
            if child.status is not _RUNNING:
                child.initialise()
            child_status = child.update()
            if child_status.__class__ is not Status:
                child_status = Status.INVALID
            if child_status is not _RUNNING:
                child.terminate(child_status)
            child.status = child_status
            yield child
        else:
            yield from child.tick()
            child_status = child.status
        if child_status is _RUNNING:
            self.status = _RUNNING
            yield self
            return
        run = self.run
        if run is None:
            new_status = child_status
        elif child_status is _SUCCESS:
            new_status = self._after_success(run)
        else:
            new_status = self._after_failure(run)
        self._finish(new_status)
        yield self

    def update(self) -> Status:
        # Never called: tick() decides. Required by py_trees' abstract Behaviour.
        return self.status

    def _finish(self, new_status: Status) -> None:
        self.stop(new_status)
        run = self.run
        if run is not None and run._trace:
            context = self._step_context(run)
            run.emit("step_end", **context.describe(), status=new_status.value,
                     state=[atom_text(a) for a in sorted(run.state)],
                     failure=None if self.failure is None else self.failure.to_dict())

    def stop(self, new_status: Status) -> None:
        # Lean version of Decorator.stop (no debug formatting on the tick path).
        child = self.decorated
        if new_status is Status.INVALID or child.status is _RUNNING:
            if self._inline:
                child.terminate(Status.INVALID)
                child.status = Status.INVALID
            else:
                child.stop(Status.INVALID)
        self.status = new_status

    # -- before -------------------------------------------------------------------------------------------------

    def _bindings(self) -> dict[str, str]:
        if self.bindings is not None and self._static:
            return self.bindings
        primitive = self.action.primitive if self.action is not None else None
        if primitive is None or self.action is None:
            return dict(self.bindings or {})
        return dict(zip(primitive.parameters, self.action.resolved_args(), strict=False))

    def _precondition_holds(self, run: RunContext) -> bool:
        state = run.state
        bindings: dict[str, str] = {}
        try:
            primitive = self.primitive
            if primitive is None:
                bindings = dict(self.bindings or {})
                if self.condition.holds(state, bindings, run._external):
                    return True
            else:
                args = self.action._static_args if self._static else self.action.resolved_args()  # type: ignore
                bindings = self._bindings()
                env = next(iter(primitive.satisfiers(state, args, run._external)), None)
                if env is not None:
                    if self._effects_need_state or not self._static:
                        self._step_effects = primitive.effects(env, state, run._external)
                    return True
        except Exception as error:  # an external-predicate plugin, a missing argument, a wrong arity
            self._record(run, Failure(
                kind=FailureKind.INTERNAL,
                message=f"precondition could not be evaluated: {type(error).__name__}: {error}",
                evidence={"condition": _source(self.condition), "error": f"{type(error).__name__}: {error}"},
                plugin=_plugin_in(str(error)),
            ))
            return False
        evidence: dict[str, Any] = {"condition": _source(self.condition), "bindings": bindings,
                                    "state": _relevant_atoms(state, self.condition)}
        if self._check_types:
            evidence["types"] = {p: t for p, t in zip(self.primitive.parameters, self.primitive.types,  # type: ignore
                                                        strict=False) if t}
        self._record(run, Failure(
            kind=FailureKind.PRECONDITION,
            message=f"precondition {_source(self.condition)} does not hold",
            evidence=evidence,
        ))
        return False

    # -- after --------------------------------------------------------------------------------------------------

    def _after_success(self, run: RunContext) -> Status:
        hooks = run.hooks
        observe = "bt_meta_observe" in hooks
        expect = "bt_meta_expectations" in hooks
        if observe or expect:
            context = self._step_context(run)
            internal = None
            observations: dict[str, Any] = {}
            if observe:
                observations, internal = self._observe(run, context, self._request(run, context))
            mismatches: list[Comparison] = []
            if internal is None and expect:
                mismatches, internal = self._compare(run, context, observations)
            self._update_belief(run, observations)
            if internal is not None:
                self.failure = internal
                return _FAILURE
            if mismatches:
                self._record_mismatch(run, context, mismatches, observations)
                return _FAILURE
            return _SUCCESS
        effects = self._step_effects
        if effects is not None:
            run.state = run.state.apply(add=effects[0], delete=effects[1])
        return _SUCCESS

    @staticmethod
    def _request(run: RunContext, context: StepContext) -> ObserveRequest:
        """What the readers of this observation will read: the monitor's belief (``symbolic_state``) and every
        key the ``bt_meta_observation_needs`` plugins name; everything while a comparison plugin has not said (it
        may read any key), only the belief when nothing reads observations."""
        plugins = run.plugins
        declared = {impl.plugin_name for impl in plugins.implementations("bt_meta_observation_needs")}  # type: ignore
        if any(impl.plugin_name not in declared
               for impl in plugins.implementations("bt_meta_compare")):  # type: ignore[union-attr]
            return OBSERVE_ALL
        if not declared:
            return BELIEF_ONLY  # nothing compares (a demonstration being recorded): only the belief is read
        result = plugins.call("bt_meta_observation_needs", context=context)  # type: ignore[union-attr]
        for error in result.errors:
            log.warning("%s; observing everything", error)
        if result.errors or any(keys is None for _, keys in result.results):
            return OBSERVE_ALL  # a reader that cannot say gets everything, as before
        wanted = {"symbolic_state"}
        for _, keys in result.results:
            wanted.update(keys)
        return ObserveRequest(frozenset(wanted))

    def _observe(self, run: RunContext, context: StepContext,
                 request: ObserveRequest) -> tuple[dict[str, Any], Failure | None]:
        result = run.plugins.call("bt_meta_observe", world=run.world, context=context,  # type: ignore[union-attr]
                                  request=request)
        observations: dict[str, Any] = {}
        for _, value in result.results:
            if not isinstance(value, dict):
                continue
            for key, item in value.items():
                observations.setdefault(key, item)
        return observations, self._contain(run, result, context)

    def _compare(self, run: RunContext, context: StepContext,
                 observations: dict[str, Any]) -> tuple[list[Comparison], Failure | None]:
        plugins = run.plugins
        result = plugins.call("bt_meta_expectations", context=context)  # type: ignore[union-attr]
        internal = self._contain(run, result, context)
        if internal is not None:
            return [], internal
        mismatches: list[Comparison] = []
        for plugin_name, expectations in result.results:
            for expectation in expectations:
                if expectation.plugin is None:
                    expectation.plugin = plugin_name
                verdict = plugins.call("bt_meta_compare", expectation=expectation,  # type: ignore[union-attr]
                                       observations=observations, context=context)
                internal = self._contain(run, verdict, context)
                if internal is not None:
                    return mismatches, internal
                if not verdict.results:
                    run.emit("uncompared", expectation=expectation.description, kind=expectation.kind,
                             **context.describe())
                    continue
                comparison: Comparison = verdict.first
                comparison.expectation = comparison.expectation or expectation
                comparison.plugin = comparison.plugin or verdict.first_plugin
                if not comparison.matched:
                    mismatches.append(comparison)
        return mismatches, None

    def _update_belief(self, run: RunContext, observations: dict[str, Any]) -> None:
        observed = observations.get("symbolic_state")
        if observed is not None:
            run.state = observed
        elif self._step_effects is not None:
            run.state = run.state.apply(add=self._step_effects[0], delete=self._step_effects[1])

    def _record_mismatch(self, run: RunContext, context: StepContext, mismatches: list[Comparison],
                         observations: dict[str, Any]) -> None:
        first = mismatches[0]
        expectation: Expectation = first.expectation  # type: ignore[assignment]
        failure = self._failure(
            context, expectation.failure_kind,
            "; ".join(m.message or (m.expectation.description if m.expectation else "mismatch") for m in mismatches),
            {"mismatches": [_comparison_record(m) for m in mismatches]},
        )
        self._classify(run, failure, mismatches, context)
        self._record(run, failure, context)

    def _after_failure(self, run: RunContext) -> Status:
        context = self._step_context(run)
        # a primitive's failure record, or one any other leaf keeps in ``failure`` (a ROS leaf: why it failed)
        reported = self.action.failure if self.action is not None else getattr(self.decorated, "failure", None)
        if not isinstance(reported, Failure):
            reported = None
        if reported is None:
            failure = self._failure(context, FailureKind.INTERNAL,
                                    f"{self.decorated.name} failed without a failure record")
            self._classify(run, failure, [], context)
        else:
            failure = reported
            failure.node_name = failure.node_name or self.decorated.name
        if "bt_meta_observe" in run.hooks:
            # after a failure only the belief is read (no comparison, and the next step observes afresh)
            observations, internal = self._observe(run, context, BELIEF_ONLY)
            self._update_belief(run, observations)
            if internal is not None:
                failure.evidence["observation_error"] = internal.message
        self._record(run, failure, context)
        return _FAILURE

    # -- records ------------------------------------------------------------------------------------------------

    def _step_context(self, run: RunContext | None) -> StepContext:
        if self.context is not None:
            if self._step_effects is not None:
                # Effects bound by the precondition check are known only after the context was first made.
                self.context.effects = self._step_effects
            return self.context
        if self.action is not None:
            context = self.action.context
            if context is None or context.run is not run:
                try:
                    context = self.action.make_context(run)
                except BtMetaError:
                    context = StepContext(action=self.action.action, args=self.action.arg_specs,
                                          node_id=self.action.node_id, step=self.action.step,
                                          node_name=self.action.name, primitive=self.action.primitive, run=run)
        else:
            context = StepContext(action=self.decorated.name, args=(), node_name=self.decorated.name,
                                  bindings=dict(self.bindings or {}), run=run,
                                  state_before=None if run is None else run.state)
        if context.effects is None:
            context.effects = self._step_effects
        self.context = context
        return context

    def _failure(self, context: StepContext, kind: FailureKind | str, message: str,
                 evidence: dict[str, Any] | None = None) -> Failure:
        return Failure(kind=kind, message=message, step=context.step, node_id=context.node_id,
                       action=context.action, args=context.args, evidence=evidence or {},
                       node_name=context.node_name)

    def _classify(self, run: RunContext, failure: Failure, mismatches: list[Comparison],
                  context: StepContext) -> None:
        plugins = run.plugins
        if plugins is None or "bt_meta_classify_failure" not in run.hooks:
            return
        result = plugins.call("bt_meta_classify_failure", failure=failure, mismatches=mismatches, context=context)
        self._contain(run, result, context)
        if result.results:
            try:
                failure.kind = parse_kind(result.first)
                failure.evidence["classified_by"] = result.first_plugin
            except BtMetaError as error:
                failure.evidence["classification_error"] = f"plugin {result.first_plugin!r}: {error}"

    def _record(self, run: RunContext, failure: Failure, context: StepContext | None = None) -> None:
        if context is None:
            context = self._step_context(run)
        if failure.action is None:
            failure.action, failure.args = context.action, tuple(context.args)
            failure.step, failure.node_id = context.step, context.node_id
            failure.node_name = failure.node_name or context.node_name
        self.failure = failure
        self.feedback_message = failure.summary()
        run.record_failure(failure, context)

    def _contain(self, run: RunContext, result: Any, context: StepContext) -> Failure | None:
        if not result.errors:
            return None
        first = run.contain(result, context)
        if first is not None:
            self.failure = first
            self.feedback_message = first.summary()
        return first


def monitor_action(behaviour: py_trees.behaviour.Behaviour, instance: Any = None) -> py_trees.behaviour.Behaviour:
    """The XML loader's ``wrap_action``: a Monitor around ``behaviour`` (named after it)."""
    return Monitor(behaviour, name=f"Monitor<{behaviour.name}>")


# -- helpers ------------------------------------------------------------------------------------------------------


def _effects_use_only_parameters(primitive: Any) -> bool:
    if getattr(primitive, "conditional", None):  # forall / when effects depend on the state
        return False
    parameters = set(primitive.parameters)
    for template in (*primitive.add, *primitive.delete):
        for term in template[1:]:
            name = getattr(term, "name", None)
            if name is not None and not isinstance(term, str) and name not in parameters:
                return False
    return True


def _source(condition: Any) -> str:
    return str(getattr(condition, "source", condition))


def _trivially_true(condition: Any) -> bool:
    trivial = getattr(condition, "trivial", None)
    return bool(trivial) if trivial is not None else _source(condition).strip() in ("", "true")


def _relevant_atoms(state: Any, condition: Any) -> list[str]:
    predicates = set(_PRED_RE.findall(_source(condition)))
    atoms = sorted(a for a in state if a[0] in predicates)
    shown = [atom_text(a) for a in atoms[:_MAX_STATE_ATOMS]]
    if len(atoms) > _MAX_STATE_ATOMS:
        shown.append(f"... {len(atoms) - _MAX_STATE_ATOMS} more")
    return shown


def _plugin_in(message: str) -> str | None:
    match = re.search(r"plugin '([^']+)'", message)
    return match.group(1) if match else None


def _comparison_record(comparison: Comparison) -> dict[str, Any]:
    expectation = comparison.expectation
    return {
        "expectation": None if expectation is None else expectation.description,
        "kind": None if expectation is None else expectation.kind,
        "plugin": comparison.plugin or (None if expectation is None else expectation.plugin),
        "message": comparison.message,
        "evidence": comparison.evidence,
    }
