"""The primitive action behaviour: runs one World skill tick by tick.

Offers:

* :class:`PrimitiveAction` -- a py_trees leaf for one primitive with ground or ``{key}`` arguments: on start it
  asks the run's world for the skill and starts it; every tick it ticks the skill; a skill that fails says why
  (``failure``), a skill that raises becomes an ``internal`` failure instead of an exception
* :func:`resolve_argument` -- a literal, or the value of a ``{key}`` blackboard reference

The action does not check preconditions or expectations: the :class:`~bt_meta.bt.monitor.Monitor` around it
does. An action without a monitor (``_monitor="false"`` in XML) records its own failures.
"""

from __future__ import annotations

import traceback
from collections.abc import Sequence
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.context import RunContext, current_run
from bt_meta.bt.expectations import StepContext
from bt_meta.bt.failures import Failure, FailureKind, parse_kind
from bt_meta.bt.nodes.base import absolute_key
from bt_meta.bt.registry import blackboard_key
from bt_meta.errors import BtMetaError

_STORAGE = py_trees.blackboard.Blackboard.storage
_SKILL_STATUS = {"RUNNING": Status.RUNNING, "SUCCESS": Status.SUCCESS, "FAILURE": Status.FAILURE}


def resolve_argument(value: str) -> str:
    """A literal argument as is; ``{key}`` read from the blackboard (a missing key is a :class:`BtMetaError`)."""
    key = blackboard_key(value)
    if key is None:
        return value
    name = absolute_key(key)
    try:
        return str(_STORAGE[name])
    except KeyError:
        raise BtMetaError(f"blackboard entry {name!r} (argument {value}) does not exist") from None


class PrimitiveAction(py_trees.behaviour.Behaviour):
    """One primitive of a plan or a tree XML, executed by the run's world.

    ``args`` are literals or ``{key}`` references resolved when the action starts. ``node_id`` and ``step`` tie
    it to the decomposition tree. After a FAILURE, ``failure`` says why.
    """

    def __init__(
        self,
        name: str,
        action: str,
        args: Sequence[str] = (),
        *,
        primitive: Any = None,
        node_id: str | None = None,
        step: int | None = None,
    ) -> None:
        super().__init__(name=name)
        self.action = action
        self.arg_specs = tuple(args)
        self._static_args = None if any(blackboard_key(a) for a in self.arg_specs) else self.arg_specs
        self.primitive = primitive
        self.node_id = node_id
        self.step = step
        self.monitored = False
        self.skill: Any = None
        self.context: StepContext | None = None
        self.failure: Failure | None = None
        self.run: RunContext | None = None

    # -- helpers ------------------------------------------------------------------------------------------------

    def resolved_args(self) -> tuple[str, ...]:
        if self._static_args is not None:
            return self._static_args
        return tuple(resolve_argument(a) for a in self.arg_specs)

    def make_context(self, run: RunContext | None) -> StepContext:
        args = self.resolved_args()
        bindings: dict[str, str] = {}
        if self.primitive is not None:
            bindings = dict(zip(self.primitive.parameters, args, strict=False))
        return StepContext(
            action=self.action,
            args=args,
            node_id=self.node_id,
            step=self.step,
            node_name=self.name,
            primitive=self.primitive,
            bindings=bindings,
            state_before=None if run is None else run.state,
            run=run,
        )

    def _fail(self, kind: FailureKind | str, message: str, evidence: dict[str, Any] | None = None) -> Status:
        context = self.context
        self.failure = Failure(
            kind=kind,
            message=message,
            step=self.step,
            node_id=self.node_id,
            action=self.action,
            args=() if context is None else context.args,
            evidence=evidence or {},
            node_name=self.name,
        )
        if not self.monitored and self.run is not None:
            self.run.record_failure(self.failure, context)
        return Status.FAILURE

    # -- py_trees -----------------------------------------------------------------------------------------------

    def initialise(self) -> None:
        self.failure = None
        self.skill = None
        run = self.run = current_run()
        try:
            self.context = self.make_context(run)
        except BtMetaError as error:
            self.context = None
            self._fail(FailureKind.INTERNAL, str(error))
            return
        if run is None or run.world is None:
            self._fail(FailureKind.INTERNAL, "no world to act on: the tree is not ticked inside a run")
            return
        run.steps_started += 1
        try:
            self.skill = run.world.skill(self.action)
            self.skill.start(self.context.args, self.context)
        except Exception as error:
            self.skill = None
            self._fail(FailureKind.INTERNAL, f"skill {self.action} could not start: {type(error).__name__}: {error}",
                       {"error": f"{type(error).__name__}: {error}", "traceback": traceback.format_exc(limit=6)})

    def update(self) -> Status:
        skill = self.skill
        if skill is None:
            return Status.FAILURE
        try:
            status = _SKILL_STATUS[skill.tick()]
        except KeyError:
            return self._fail(FailureKind.INTERNAL, f"skill {self.action} returned a status that is not "
                                                    "RUNNING, SUCCESS or FAILURE")
        except Exception as error:
            self.skill = None
            return self._fail(FailureKind.INTERNAL, f"skill {self.action} raised {type(error).__name__}: {error}",
                              {"error": f"{type(error).__name__}: {error}",
                               "traceback": traceback.format_exc(limit=6)})
        if status is Status.FAILURE:
            reported = getattr(skill, "failure", None)
            if reported is None:
                return self._fail(FailureKind.INTERNAL,
                                  f"skill {self.action} reported FAILURE without a failure kind")
            try:
                kind = parse_kind(reported.kind)
            except BtMetaError as error:
                return self._fail(FailureKind.INTERNAL, f"skill {self.action}: {error}")
            evidence = dict(reported.evidence)
            record = getattr(skill, "record", None)
            if record is not None:
                evidence.setdefault("skill", record())
            return self._fail(kind, reported.message, evidence)
        return status

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.skill is not None and self.status == Status.RUNNING:
            cancel = getattr(self.skill, "cancel", None)
            if cancel is not None:
                cancel()
