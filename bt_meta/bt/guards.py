"""Guards: a method's precondition as a condition node of the tree.

Offers:

* :class:`CheckCondition` -- SUCCESS when a condition holds in the run's belief state under some bindings (literals
  or ``{key}`` blackboard references); it can write the variables it binds to the blackboard (policy trees bind
  a method's free variables at run time) and record a ``precondition`` failure when it does not hold
* :func:`parse_bindings`, :func:`format_bindings` -- the ``var=value;var={key}`` text of the ``bindings`` port
* :func:`compile_guard` -- condition text -> compiled HTN condition for a domain
"""

from __future__ import annotations

import traceback
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.actions import resolve_argument
from bt_meta.bt.context import current_run
from bt_meta.bt.failures import Failure, FailureKind
from bt_meta.bt.nodes.base import absolute_key
from bt_meta.errors import BtMetaError
from bt_meta.htn.state import State

_STORAGE = py_trees.blackboard.Blackboard.storage
_EMPTY_STATE = State()


class GuardError(BtMetaError):
    """A guard whose condition or bindings do not parse."""


def parse_bindings(text: str) -> dict[str, str]:
    """``"b=b0; x={p1_x}"`` -> ``{"b": "b0", "x": "{p1_x}"}``."""
    bindings: dict[str, str] = {}
    for part in text.split(";"):
        part = part.strip()
        if not part:
            continue
        name, sep, value = part.partition("=")
        name = name.strip().lstrip("?")
        if not sep or not name or not value.strip():
            raise GuardError(f"bad binding {part!r}: expected var=value")
        bindings[name] = value.strip()
    return bindings


def format_bindings(bindings: dict[str, str]) -> str:
    return ";".join(f"{name}={value}" for name, value in bindings.items())


def compile_guard(text: str, domain: Any, bound: Any) -> Any:
    """Compile condition ``text`` against ``domain``'s predicates, ``bound`` naming the variables given values."""
    from bt_meta.htn.conditions import ConditionSyntaxError, compile_condition, parse_condition

    try:
        return compile_condition(text, parse_condition(text), domain.context, bound)
    except ConditionSyntaxError as error:
        raise GuardError(f"condition {text!r}: {error} (at offset {error.offset})") from None
    except BtMetaError as error:
        raise GuardError(f"condition {text!r}: {error}") from None


class CheckCondition(py_trees.behaviour.Behaviour):
    """A method precondition (or any condition) checked against the run's belief state."""

    def __init__(
        self,
        name: str,
        condition: Any,
        bindings: dict[str, str] | None = None,
        *,
        output_prefix: str | None = None,
        record: bool = True,
        method: str | None = None,
        node_id: str | None = None,
    ) -> None:
        super().__init__(name=name)
        self.condition = condition
        self.bindings = dict(bindings or {})
        self.output_prefix = output_prefix
        self.record = record
        self.method = method
        self.node_id = node_id
        self.failure: Failure | None = None
        self.found: dict[str, str] | None = None

    def update(self) -> Status:
        run = current_run()
        state = _EMPTY_STATE if run is None else run.state
        self.failure = None
        try:
            env = {name: resolve_argument(value) for name, value in self.bindings.items()}
            found = next(iter(self.condition.satisfiers(state, env, None if run is None else run.external)), None)
        except Exception as error:
            self._fail(run, FailureKind.INTERNAL, f"guard {self.name!r} could not be evaluated: "
                       f"{type(error).__name__}: {error}", {"traceback": traceback.format_exc(limit=6)}, force=True)
            return Status.FAILURE
        self.found = found
        if found is None:
            self._fail(run, FailureKind.PRECONDITION,
                       f"precondition of method {self.method or '?'} does not hold: {self.condition.source}",
                       {"condition": self.condition.source, "bindings": env})
            return Status.FAILURE
        if self.output_prefix is not None:
            for name, value in found.items():
                _STORAGE[absolute_key(f"{self.output_prefix}{name}")] = value
        return Status.SUCCESS

    def _fail(self, run: Any, kind: FailureKind, message: str, evidence: dict[str, Any], force: bool = False) -> None:
        self.failure = Failure(kind=kind, message=message, node_id=self.node_id, evidence=evidence,
                               node_name=self.name, action=None)
        self.feedback_message = message
        if run is not None and (self.record or force):
            run.record_failure(self.failure)
