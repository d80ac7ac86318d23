"""A fake symbolic world for tests and for ``bt-meta tick --world fake``.

Its state is the problem's initial facts; each skill takes a configurable number of ticks and then applies its
primitive's add and delete effects. Scripted faults make the failures a monitor must catch reproducible.

Offers:

* :class:`FakeWorld` -- the world (implements :class:`bt_meta.world.base.World`)
* :class:`FakeSkill` -- one execution of a primitive in it
* :class:`Fault` -- a scripted fault: fail with a kind, succeed with an effect that silently did not happen
  (all or some atoms), or raise; :meth:`Fault.parse` reads ``ACTION[(ARGS)][#N]=MODE[:KIND]``
* :func:`bt_meta_make_world` -- the hook implementation that makes ``--world fake`` (a built-in plugin)
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from bt_meta.bt.failures import FailureKind, parse_kind
from bt_meta.errors import BtMetaError, UserInputError
from bt_meta.hookspecs import hookimpl
from bt_meta.htn.state import State, atom_text
from bt_meta.world.base import FAILURE, RUNNING, SUCCESS, Atom, SkillFailure, ground_effects

FAULT_MODES = ("fail", "silent", "partial", "raise")
_FAULT_RE = re.compile(
    r"^\s*(?P<action>[A-Za-z_][\w\-]*)\s*(?:\((?P<args>[^()]*)\))?\s*(?:#(?P<occ>\d+))?\s*=\s*"
    r"(?P<mode>[a-z]+)\s*(?::\s*(?P<kind>\w+))?\s*$"
)


class FaultSpecError(UserInputError):
    """A ``--fault`` specification that does not parse."""


@dataclass
class Fault:
    """A scripted fault of the fake world.

    ``args=None`` matches any arguments; ``occurrence`` (1-based) picks the n-th matching execution, ``None``
    every one. Modes: ``fail`` (the skill reports FAILURE with ``kind``), ``silent`` (reports SUCCESS but no effect
    happens), ``partial`` (SUCCESS, but the atoms in ``drop`` are not added / not deleted), ``raise`` (the skill
    raises ``RuntimeError``).
    """

    action: str
    mode: str = "fail"
    kind: FailureKind = FailureKind.PHYSICAL
    args: tuple[str, ...] | None = None
    occurrence: int | None = None
    message: str = ""
    drop: tuple[Atom, ...] = ()

    def __post_init__(self) -> None:
        if self.mode not in FAULT_MODES:
            raise BtMetaError(f"unknown fault mode {self.mode!r}; expected one of: {', '.join(FAULT_MODES)}")
        self.kind = parse_kind(self.kind)
        if self.args is not None:
            self.args = tuple(self.args)
        self.drop = tuple(tuple(atom) for atom in self.drop)

    @classmethod
    def parse(cls, text: str) -> Fault:
        """``place(b0, 2, 1)#1=fail:physical``, ``place=silent``, ``pick=raise`` -> a :class:`Fault`."""
        match = _FAULT_RE.match(text)
        if not match:
            raise FaultSpecError(
                f"bad fault {text!r}: expected ACTION[(ARG, ...)][#N]=MODE[:KIND] with MODE one of "
                f"{', '.join(FAULT_MODES)}"
            )
        args = None
        if match["args"] is not None:
            args = tuple(part.strip() for part in match["args"].split(",") if part.strip())
        try:
            return cls(
                action=match["action"],
                mode=match["mode"],
                kind=match["kind"] or FailureKind.PHYSICAL,
                args=args,
                occurrence=int(match["occ"]) if match["occ"] else None,
            )
        except BtMetaError as error:
            raise FaultSpecError(f"bad fault {text!r}: {error}") from None

    def matches(self, action: str, args: tuple[str, ...], occurrence: int) -> bool:
        if action != self.action or (self.args is not None and self.args != args):
            return False
        return self.occurrence is None or self.occurrence == occurrence


class FakeSkill:
    """One execution of a primitive in a :class:`FakeWorld`: RUNNING for ``ticks - 1`` ticks, then the outcome."""

    def __init__(self, world: FakeWorld, primitive: Any, ticks: int) -> None:
        self.world = world
        self.primitive = primitive
        self.ticks_needed = max(1, ticks)
        self.ticks = 0
        self.args: tuple[str, ...] = ()
        self.fault: Fault | None = None
        self.failure: SkillFailure | None = None
        self.outcome: str | None = None
        self.cancelled = False
        self.external: Any = None

    def start(self, args: Sequence[str], ctx: Any = None) -> None:
        self.args = tuple(args)
        if len(self.args) != len(self.primitive.parameters):
            raise BtMetaError(
                f"{self.primitive.name} takes {len(self.primitive.parameters)} arguments, got {len(self.args)}"
            )
        self.fault = self.world._next_fault(self.primitive.name, self.args)
        run = getattr(ctx, "run", None)
        self.external = None if run is None else run.external
        self.ticks = 0
        self.failure = None
        self.outcome = None

    def tick(self) -> str:
        self.ticks += 1
        self.world.total_ticks += 1
        if self.ticks < self.ticks_needed:
            return RUNNING
        fault = self.fault
        call = f"{self.primitive.name}({', '.join(self.args)})"
        if fault is not None and fault.mode == "raise":
            self.outcome = "raised"
            raise RuntimeError(fault.message or f"scripted fault: {call} raised")
        if fault is not None and fault.mode == "fail":
            self.outcome = FAILURE
            self.failure = SkillFailure(
                kind=fault.kind.value,
                message=fault.message or f"scripted fault: {call} failed",
                evidence={"fault": "fail", "ticks": self.ticks},
            )
            return FAILURE
        effects = ground_effects(self.primitive, self.args, self.world.symbolic_state(), self.external)
        if effects is None:
            self.outcome = FAILURE
            self.failure = SkillFailure(
                kind=FailureKind.PRECONDITION.value,
                message=f"{call} cannot run in the fake world: its precondition "
                f"{self.primitive.precondition.source} does not hold in the true state",
                evidence={"condition": self.primitive.precondition.source},
            )
            return FAILURE
        add, delete = effects
        if fault is not None and fault.mode == "silent":
            add, delete = [], []
        elif fault is not None and fault.mode == "partial":
            dropped = set(fault.drop)
            add = [a for a in add if a not in dropped]
            delete = [a for a in delete if a not in dropped]
        self.world.apply_symbolic(add, delete)
        self.outcome = SUCCESS
        return SUCCESS

    def cancel(self) -> None:
        self.cancelled = True
        self.outcome = "cancelled"

    def record(self) -> dict[str, Any]:
        return {
            "action": self.primitive.name,
            "args": list(self.args),
            "ticks": self.ticks,
            "outcome": self.outcome,
            "fault": None if self.fault is None else self.fault.mode,
        }


class FakeWorld:
    """A symbolic world: the problem's initial state, skills that apply their primitive's effects.

    ``ticks_per_skill`` is an int for every action or a mapping ``action -> ticks`` (missing actions take 1).
    """

    def __init__(
        self,
        domain: Any,
        problem: Any = None,
        *,
        ticks_per_skill: int | Mapping[str, int] = 1,
        faults: Iterable[Fault | str] = (),
        state: State | Iterable[Atom] | None = None,
    ) -> None:
        self.domain = domain
        self.problem = problem
        if state is not None:
            self._state = state if isinstance(state, State) else State(state)
        else:
            self._state = initial_state(problem)
        self.ticks_per_skill = ticks_per_skill
        self.faults = [fault if isinstance(fault, Fault) else Fault.parse(fault) for fault in faults]
        self._occurrences: dict[tuple[str, tuple[str, ...]], int] = {}
        self._action_occurrences: dict[str, int] = {}
        self.executed: list[FakeSkill] = []
        self.total_ticks = 0

    def symbolic_state(self) -> State:
        return self._state

    def apply_symbolic(self, add: Iterable[Atom], delete: Iterable[Atom]) -> None:
        self._state = self._state.apply(add=add, delete=delete)

    def skill(self, action: str) -> FakeSkill:
        primitive = self.domain.primitives.get(action) if self.domain is not None else None
        if primitive is None:
            known = ", ".join(sorted(self.domain.primitives)) if self.domain is not None else "none (no domain)"
            raise BtMetaError(f"the fake world has no skill {action!r}; known primitives: {known}")
        if isinstance(self.ticks_per_skill, Mapping):
            ticks = int(self.ticks_per_skill.get(action, 1))
        else:
            ticks = int(self.ticks_per_skill)
        skill = FakeSkill(self, primitive, ticks)
        self.executed.append(skill)
        return skill

    def observe(self) -> dict[str, Any]:
        return {"symbolic_state": self._state, "objects": {}}

    def _next_fault(self, action: str, args: tuple[str, ...]) -> Fault | None:
        key = (action, args)
        self._occurrences[key] = self._occurrences.get(key, 0) + 1
        self._action_occurrences[action] = self._action_occurrences.get(action, 0) + 1
        for fault in self.faults:
            occurrence = self._occurrences[key] if fault.args is not None else self._action_occurrences[action]
            if fault.matches(action, args, occurrence):
                return fault
        return None

    def describe_state(self) -> list[str]:
        return [atom_text(atom) for atom in sorted(self._state)]


def initial_state(problem: Any) -> State:
    """The problem's initial state, whether the model keeps it as a :class:`State` or as atoms."""
    if problem is None:
        return State()
    for attribute in ("state", "initial_state", "init"):
        value = getattr(problem, attribute, None)
        if value is None:
            continue
        if callable(value):
            value = value()
        return value if isinstance(value, State) else State(value)
    raise BtMetaError(f"cannot find the initial state of problem {problem!r}")


@hookimpl
def bt_meta_make_world(name: str, domain: Any, problem: Any, options: dict[str, Any]) -> FakeWorld | None:
    if name != "fake":
        return None
    return FakeWorld(
        domain,
        problem,
        ticks_per_skill=options.get("ticks_per_skill", 1),
        faults=options.get("faults", ()),
    )
