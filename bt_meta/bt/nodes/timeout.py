"""BehaviorTree.CPP's ``Timeout`` decorator with an injectable clock.

Offers:

* :class:`Timeout` -- FAILURE (child halted) when the child is still RUNNING ``msec`` milliseconds after it started

BT.CPP halts the child from a timer thread the moment the deadline passes and returns FAILURE at the next tick; we
have no threads, so the child is halted at that next tick, just before FAILURE is returned. The observable statuses
are the same; only the moment of the child's ``halt()`` differs. ``msec="0"`` never times out (as in BT.CPP).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import DecoratorNode, PortValue, TickGenerator


class Timeout(DecoratorNode):
    """BT.CPP ``Timeout``; ``clock`` returns seconds (``time.monotonic`` by default)."""

    def __init__(
        self,
        name: str,
        child: py_trees.behaviour.Behaviour,
        msec: PortValue | int,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(name, child)
        self.msec = msec
        self.clock = clock
        self.timeout_started = False
        self.deadline: float | None = None

    def execute(self) -> TickGenerator:
        if not self.timeout_started:
            msec = self.msec.get() if isinstance(self.msec, PortValue) else self.msec
            self.timeout_started = True
            self.status = Status.RUNNING
            self.deadline = self.clock() + msec / 1000.0 if msec > 0 else None
        if self.deadline is not None and self.clock() >= self.deadline and self.decorated.status == Status.RUNNING:
            self.reset_child()
            self.timeout_started = False
            return Status.FAILURE
        child_status = yield from self.tick_child()
        if child_status in (Status.SUCCESS, Status.FAILURE):
            self.timeout_started = False
            self.reset_child()
        return child_status

    def halt(self) -> None:
        self.timeout_started = False
        super().halt()
