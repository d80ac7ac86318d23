"""BehaviorTree.CPP's waiting nodes, with an injectable clock.

Offers:

* :class:`Delay` -- RUNNING for ``delay_msec`` milliseconds, then ticks its child until it finishes
* :class:`Sleep` -- RUNNING for ``msec`` milliseconds, then SUCCESS (``msec="0"``: SUCCESS at once)

BT.CPP's timer thread raises the tree's wake-up signal when the time is up; without threads we check the clock when
ticked, so the node finishes at the first tick after the deadline (the statuses seen per tick are the same).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import DecoratorNode, PortValue, TickGenerator

Clock = Callable[[], float]


def _msec(value: PortValue | int) -> int:
    return value.get() if isinstance(value, PortValue) else value


class Delay(DecoratorNode):
    """BT.CPP ``Delay``."""

    def __init__(
        self, name: str, child: py_trees.behaviour.Behaviour, delay_msec: PortValue | int, clock: Clock = time.monotonic
    ) -> None:
        super().__init__(name, child)
        self.delay_msec = delay_msec
        self.clock = clock
        self.deadline: float | None = None

    def execute(self) -> TickGenerator:
        msec = _msec(self.delay_msec)
        if self.deadline is None:
            self.status = Status.RUNNING
            self.deadline = self.clock() + msec / 1000.0
        if self.clock() < self.deadline:
            return Status.RUNNING
        status = yield from self.tick_child()
        if status in (Status.SUCCESS, Status.FAILURE):
            self.deadline = None
            self.reset_child()
        return status

    def halt(self) -> None:
        self.deadline = None
        super().halt()


class Sleep(py_trees.behaviour.Behaviour):
    """BT.CPP ``Sleep``."""

    def __init__(self, name: str, msec: PortValue | int, clock: Clock = time.monotonic) -> None:
        super().__init__(name)
        self.msec = msec
        self.clock = clock
        self.deadline: float | None = None

    def initialise(self) -> None:
        msec = _msec(self.msec)
        self.deadline = self.clock() + msec / 1000.0 if msec > 0 else None

    def update(self) -> Status:
        if self.deadline is None or self.clock() >= self.deadline:
            return Status.SUCCESS
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.deadline = None
