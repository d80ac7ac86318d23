"""Structured failures: what went wrong at which step, of which kind, with which evidence.

A behaviour tree on its own only says FAILURE. bt-meta's monitors record *why*: a kind from the failure taxonomy
(``DESIGN.md``), the step and decomposition node, the action and its arguments, and the evidence a plugin found.

Offers:

* :class:`FailureKind` -- the taxonomy kinds (a ``str`` enum, so records stay JSON-able)
* :class:`Failure` -- one recorded failure; :meth:`Failure.to_dict` is what lands on ``/bt_meta/failures``
* :class:`RepairProposal` -- what a repair plugin answers to a failure (ranked by ``score``)
* :func:`parse_kind` -- a kind from user or plugin input, with a clear error listing the valid kinds
"""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass, field
from typing import Any

from bt_meta.errors import BtMetaError


class FailureKind(str, enum.Enum):
    """Failure taxonomy; the string values are what records and plugins use."""

    PRECONDITION = "precondition"
    """Hard: a symbolic precondition does not hold (replan symbolically)."""
    UNKNOWN_ENTITY = "unknown_entity"
    """Logical: an entity the plan needs is missing and unknown ones are present."""
    UNEXPECTED_CONFIGURATION = "unexpected_configuration"
    """Logical: known entities in an unseen configuration."""
    VERIFICATION = "verification"
    """Soft: every skill reported success but the verification procedure fails."""
    REACHABILITY = "reachability"
    """Motion: no IK solution, singular, or out of the workspace."""
    COLLISION = "collision"
    """Motion: the required pose collides."""
    PHYSICAL = "physical"
    """The gripper lost or never held the object."""
    INTERNAL = "internal"
    """A plugin or a skill raised; recorded, never crashes the tree."""

    def __str__(self) -> str:
        return self.value


KINDS: tuple[str, ...] = tuple(kind.value for kind in FailureKind)


def parse_kind(value: str | FailureKind) -> FailureKind:
    """Return the :class:`FailureKind` for ``value``; unknown strings raise a :class:`BtMetaError` naming the kinds."""
    if isinstance(value, FailureKind):
        return value
    try:
        return FailureKind(value)
    except ValueError:
        raise BtMetaError(f"unknown failure kind {value!r}; expected one of: {', '.join(KINDS)}") from None


@dataclass
class Failure:
    """One recorded failure of a monitored step (or of a guard, or of a plugin).

    ``step`` is the primitive's index in the plan (``None`` outside a plan, e.g. a policy tree or a guard);
    ``node_id`` the decomposition-node id (``"n3"``) the behaviour came from, so repairs can find the HTN node;
    ``plugin`` names the plugin that raised, for ``internal`` failures caused by a plugin.
    """

    kind: FailureKind
    message: str
    step: int | None = None
    node_id: str | None = None
    action: str | None = None
    args: tuple[str, ...] = ()
    evidence: dict[str, Any] = field(default_factory=dict)
    plugin: str | None = None
    node_name: str | None = None
    tick: int | None = None

    def __post_init__(self) -> None:
        self.kind = parse_kind(self.kind)
        self.args = tuple(self.args)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able record (``kind`` as its string value, ``args`` as a list)."""
        record = asdict(self)
        record["kind"] = self.kind.value
        record["args"] = list(self.args)
        return record

    @classmethod
    def from_dict(cls, record: dict[str, Any]) -> Failure:
        known = {name for name in cls.__dataclass_fields__}
        return cls(**{key: value for key, value in record.items() if key in known})

    def summary(self) -> str:
        """One line for logs and the CLI: ``[kind] node step action(args): message``."""
        where = " ".join(part for part in (self.node_id, None if self.step is None else f"step {self.step}") if part)
        call = f"{self.action}({', '.join(self.args)})" if self.action else ""
        head = " ".join(part for part in (where, call) if part)
        by = f" (plugin {self.plugin})" if self.plugin else ""
        return f"[{self.kind.value}] {head + ': ' if head else ''}{self.message}{by}"


@dataclass
class RepairProposal:
    """A change to the plan a repair plugin proposes: substitute an object, backtrack to step k, replan from node n.

    ``action`` says which kind of change (``"substitute"``, ``"backtrack"``, ``"replan"``, ``"retry"``, ...);
    ``changes`` holds its parameters; the meta-reasoner applies the best-scored proposal first.
    """

    action: str
    score: float
    description: str = ""
    changes: dict[str, Any] = field(default_factory=dict)
    evidence: dict[str, Any] = field(default_factory=dict)
    plugin: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
