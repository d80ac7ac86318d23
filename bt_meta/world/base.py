"""The protocols between behaviour trees and the worlds they act on.

A primitive action behaviour asks the world for the skill of its action, starts it with ground arguments and
ticks it until it reports SUCCESS or FAILURE; a failed skill says why with a taxonomy kind. Perception plugins
observe the world after a skill succeeded.

Offers:

* :class:`World` -- ``symbolic_state``, ``apply_symbolic``, ``skill``, ``observe``
* :class:`Skill` -- ``start``, ``tick``, ``failure``, ``record`` (and optionally ``cancel``)
* :class:`SkillFailure` -- the kind, message and evidence of a failed skill
* :data:`RUNNING`, :data:`SUCCESS`, :data:`FAILURE` -- the strings ``Skill.tick`` returns
* :func:`ground_effects` -- a primitive's ground add and delete lists for some arguments
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from bt_meta.htn.state import State

RUNNING = "RUNNING"
SUCCESS = "SUCCESS"
FAILURE = "FAILURE"
SKILL_STATUSES = (RUNNING, SUCCESS, FAILURE)

Atom = tuple[str, ...]


@dataclass
class SkillFailure:
    """Why a skill failed: ``kind`` from the failure taxonomy, a message, and evidence (JSON-able)."""

    kind: str
    message: str
    evidence: dict[str, Any] = field(default_factory=dict)


@runtime_checkable
class Skill(Protocol):
    """One execution of an action in a world, advanced one tick at a time."""

    failure: SkillFailure | None

    def start(self, args: Sequence[str], ctx: Any) -> None:
        """Begin executing with ground arguments; ``ctx`` is the step's StepContext."""

    def tick(self) -> str:
        """Advance one tick; return ``"RUNNING"``, ``"SUCCESS"`` or ``"FAILURE"`` (then ``failure`` is set)."""

    def record(self) -> dict[str, Any]:
        """A JSON-able account of this execution for traces (ticks used, targets, outcome)."""


@runtime_checkable
class World(Protocol):
    """Something primitives act on and perception observes."""

    def symbolic_state(self) -> State:
        """The ground-truth symbolic state (a fake world's own; a simulator's derived from object poses)."""

    def apply_symbolic(self, add: Iterable[Atom], delete: Iterable[Atom]) -> None:
        """Change the symbolic state directly (fake worlds, scripted scenes, tests)."""

    def skill(self, action: str) -> Skill:
        """A fresh skill for ``action``; an unknown action raises a :class:`~bt_meta.errors.BtMetaError`."""

    def observe(self) -> dict[str, Any]:
        """Object states and whatever else the world exposes to perception plugins."""


def ground_effects(
    primitive: Any, args: Sequence[str], state: State, external: Any = None
) -> tuple[list[Atom], list[Atom]] | None:
    """The primitive's ground ``(add, delete)`` lists for ``args`` in ``state``, ``None`` if its precondition fails.

    Effects may use variables the precondition binds (SHOP2 style), hence the state.
    """
    env = next(iter(primitive.satisfiers(state, tuple(args), external)), None)
    if env is None:
        return None
    return primitive.effects(env, state, external)
