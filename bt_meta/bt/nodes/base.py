"""Base classes that give py_trees behaviours BehaviorTree.CPP's tick, halt and reset discipline.

BehaviorTree.CPP and py_trees disagree on what happens to a child that finished: BehaviorTree.CPP keeps its
SUCCESS/FAILURE until the parent *resets* it (status back to IDLE, no callback) and only *halts* (calls
``halt()``) a child that is RUNNING. py_trees calls ``stop(INVALID)`` on any child that is not INVALID. The classes
here follow BehaviorTree.CPP, mapping IDLE to py_trees' INVALID.

Offers:

* :func:`reset_child` -- BehaviorTree.CPP's ``haltChild``: halt if RUNNING, then reset to INVALID
* :class:`ControlNode` -- a py_trees composite whose subclasses write ``execute()`` like BT.CPP's ``tick()``
* :class:`DecoratorNode` -- the same for decorators
* :class:`PortValue` -- a port given as a literal or a ``{key}``, read (and converted) at tick time
* :class:`WakeUpSignal` -- BehaviorTree.CPP's wake-up signal (see :mod:`bt_meta.bt.nodes.ticking`)
"""

from __future__ import annotations

from collections.abc import Generator, Iterator
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes import entries
from bt_meta.bt.nodes.entries import absolute_key
from bt_meta.bt.nodes.status import SKIPPED, Returned, mark, returned
from bt_meta.bt.registry import PortSpec, blackboard_key
from bt_meta.errors import BtMetaError

TickGenerator = Generator[py_trees.behaviour.Behaviour, None, Returned]

__all__ = ["SKIPPED", "absolute_key"]


class PortValueError(BtMetaError):
    """A ``{key}`` port whose blackboard entry is missing or has the wrong type at tick time."""


class WakeUpSignal:
    """Raised by Repeat/Retry when a child finished synchronously; a ``tick_once`` ticks the root again.

    BehaviorTree.CPP installs one in every node of a tree; nodes outside a tree have none and loop within the
    tick instead. We do the same: ``wake_up is None`` means "loop in place".
    """

    def __init__(self) -> None:
        self.pending = False

    def emit(self) -> None:
        self.pending = True

    def consume(self) -> bool:
        pending, self.pending = self.pending, False
        return pending


def reset_child(child: py_trees.behaviour.Behaviour) -> None:
    """Halt ``child`` if it is RUNNING, otherwise reset it to INVALID quietly (no ``terminate`` call)."""
    if child.status == Status.RUNNING:
        child.stop(Status.INVALID)
    else:
        child.status = Status.INVALID


class PortValue:
    """A port as given to a factory: a literal converted once, or a ``{key}`` read from the blackboard per tick."""

    def __init__(self, spec: PortSpec, text: str | None) -> None:
        self.spec = spec
        self.text = text
        self.key = blackboard_key(text)
        self._literal: Any = None
        if text is not None and self.key is None:
            self._literal = spec.convert(text)

    def get(self) -> Any:
        if self.key is None:
            return self._literal
        name = absolute_key(self.key)
        try:
            value = py_trees.blackboard.Blackboard.get(name)
        except KeyError:
            raise PortValueError(f"port {self.spec.name!r}: blackboard entry {name!r} does not exist") from None
        if isinstance(value, str):
            try:
                return self.spec.convert(value)
            except ValueError as error:
                raise PortValueError(str(error)) from None
        return value

    def set(self, value: Any) -> None:
        if self.key is None:
            raise PortValueError(f"output port {self.spec.name!r} must be a {{key}}, got {self.text!r}")
        entries.write(self.key, value)


class _BTNodeMixin:
    """Shared tick/stop logic; ``execute()`` is the BT.CPP ``tick()`` written as a generator returning a status."""

    wake_up: WakeUpSignal | None
    status: Status

    def execute(self) -> TickGenerator:  # pragma: no cover - abstract
        raise NotImplementedError

    def halt(self) -> None:
        """BehaviorTree.CPP ``halt()``: reset internal state and children (called when interrupted)."""
        raise NotImplementedError

    def requires_wake_up(self) -> bool:
        return self.wake_up is not None

    def emit_wake_up(self) -> None:
        if self.wake_up is not None:
            self.wake_up.emit()

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        behaviour: Any = self
        behaviour.logger.debug(f"{self.__class__.__name__}.tick()")
        if self.status != Status.RUNNING:
            behaviour.initialise()
        status = yield from self.execute()
        mark(behaviour, status)
        if status is not SKIPPED:
            # BT.CPP keeps the node's own status when it returns SKIPPED (RUNNING if it had set itself RUNNING).
            if status != Status.RUNNING:
                behaviour.terminate(status)
            self.status = status  # type: ignore[assignment]
        yield behaviour

    def stop(self, new_status: Status = Status.INVALID) -> None:
        behaviour: Any = self
        if new_status == Status.INVALID:
            self.halt()
        behaviour.terminate(new_status)
        self.status = new_status
        behaviour.iterator = behaviour.tick()


class ControlNode(_BTNodeMixin, py_trees.composites.Composite):
    """A composite ticking its children the BehaviorTree.CPP way."""

    def __init__(self, name: str, children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
        super().__init__(name, children)
        self.wake_up: WakeUpSignal | None = None

    def tick_child(self, index: int) -> TickGenerator:
        child = self.children[index]
        self.current_child = child
        yield from child.tick()
        return returned(child)

    def reset_child(self, index: int) -> None:
        reset_child(self.children[index])

    def reset_children(self, start: int = 0) -> None:
        for child in self.children[start:]:
            reset_child(child)

    def halt(self) -> None:
        self.reset_children()


class DecoratorNode(_BTNodeMixin, py_trees.decorators.Decorator):
    """A decorator ticking its child the BehaviorTree.CPP way."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name=name, child=child)
        self.wake_up: WakeUpSignal | None = None

    def tick_child(self) -> TickGenerator:
        yield from self.decorated.tick()
        return returned(self.decorated)

    def reset_child(self) -> None:
        reset_child(self.decorated)

    def halt(self) -> None:
        self.reset_child()

    def update(self) -> Status:  # unused: execute() decides
        return self.status
