"""What a monitored step passes to plugins, and what expectation plugins answer.

Offers:

* :class:`StepContext` -- one execution of a primitive: action, arguments, decomposition node, plan step, the
  primitive and its bindings, the belief state before it ran, the world and the run
* :class:`Expectation` -- something that should hold after a step (symbolic post-condition, grid-map crop,
  keypoint relation), tagged with its ``kind`` so the right comparison plugin picks it up
* :class:`Comparison` -- a comparison plugin's verdict on one expectation against the observations
* :class:`ObserveRequest` -- which observation keys the step's readers will read (``bt_meta_observe``'s
  ``request``): an observe plugin skips what nobody reads (a camera render costs 15-150 ms)
* :data:`OBSERVE_ALL` -- the request for everything (a reader that did not say what it reads)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bt_meta.bt.failures import FailureKind

if TYPE_CHECKING:
    from bt_meta.bt.context import RunContext


@dataclass(frozen=True)
class ObserveRequest:
    """The observation keys someone will read after this observation (``keys``; ``None``: any key, the request
    when a reader of observations did not declare what it reads). Observe plugins may produce more; a key not
    wanted is never read, so producing it is wasted work (a camera frame nobody looks at)."""

    keys: frozenset[str] | None = None

    def wants(self, *keys: str) -> bool:
        """Whether any of ``keys`` will be read."""
        return self.keys is None or any(key in self.keys for key in keys)


OBSERVE_ALL = ObserveRequest()


@dataclass
class StepContext:
    """One execution of one primitive, as the monitor around it sees it.

    ``primitive`` is the HTN primitive (``None`` when a tree XML names an action the domain does not know);
    ``bindings`` maps its parameter names (without ``?``) to the ground arguments; ``state_before`` is the belief
    state when the step started.
    """

    action: str
    args: tuple[str, ...]
    node_id: str | None = None
    step: int | None = None
    node_name: str | None = None
    primitive: Any = None
    bindings: dict[str, str] = field(default_factory=dict)
    state_before: Any = None
    run: RunContext | None = None
    effects: tuple[list[tuple[str, ...]], list[tuple[str, ...]]] | None = None
    """The ground ``(add, delete)`` the step should cause, under the binding its precondition was checked with."""

    @property
    def world(self) -> Any:
        return None if self.run is None else self.run.world

    @property
    def domain(self) -> Any:
        return None if self.run is None else self.run.domain

    @property
    def tick(self) -> int | None:
        return None if self.run is None else self.run.tick_count

    def describe(self) -> dict[str, Any]:
        """A JSON-able summary for trace events."""
        return {
            "action": self.action,
            "args": list(self.args),
            "node_id": self.node_id,
            "step": self.step,
            "node_name": self.node_name,
        }


@dataclass
class Expectation:
    """Something that should hold after a step.

    ``kind`` routes it to a comparison plugin (``"symbolic"``, ``"gridmap"``, ``"keypoint"``, ...); ``data`` is
    whatever that plugin needs; ``failure_kind`` is the taxonomy kind to use for a mismatch when no
    classification plugin decides otherwise.
    """

    kind: str
    description: str
    data: dict[str, Any] = field(default_factory=dict)
    failure_kind: FailureKind = FailureKind.UNEXPECTED_CONFIGURATION
    plugin: str | None = None


@dataclass
class Comparison:
    """A comparison plugin's verdict on one expectation: ``matched`` or not, with evidence for a mismatch."""

    matched: bool
    message: str = ""
    evidence: dict[str, Any] = field(default_factory=dict)
    expectation: Expectation | None = None
    plugin: str | None = None
