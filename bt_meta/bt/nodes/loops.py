"""BehaviorTree.CPP's looping decorators.

Offers:

* :class:`Repeat` -- ticks its child until it succeeded ``num_cycles`` times (``-1``: forever); a FAILURE stops
* :class:`RetryUntilSuccessful` -- ticks its child until it succeeds, at most ``num_attempts`` times (``-1``: forever)

Both loop *within one tick* while the child keeps finishing, exactly like BT.CPP, with BT.CPP's exception: inside
a tree with a wake-up signal (every tree BT.CPP builds, and every tree our XML reader builds) a child that
finished *synchronously* (it was idle when ticked) ends the tick with RUNNING and raises the signal, so that
``tick_once`` re-ticks the root and ``tick_exactly_once`` makes one iteration per tick. py_trees' Repeat/Retry
always take one iteration per tick and count differently, so these classes re-implement BT.CPP's ``tick()``.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import DecoratorNode, PortValue, TickGenerator


def _read(value: PortValue | int) -> int:
    return value.get() if isinstance(value, PortValue) else value


class Repeat(DecoratorNode):
    """BT.CPP ``Repeat``."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, num_cycles: PortValue | int) -> None:
        super().__init__(name, child)
        self.num_cycles = num_cycles
        self.repeat_count = 0

    def execute(self) -> TickGenerator:
        cycles = _read(self.num_cycles)
        do_loop = self.repeat_count < cycles or cycles == -1
        self.status = Status.RUNNING
        while do_loop:
            previous = self.decorated.status
            child_status = yield from self.tick_child()
            if child_status == Status.SUCCESS:
                self.repeat_count += 1
                do_loop = self.repeat_count < cycles or cycles == -1
                self.reset_child()
                if self.requires_wake_up() and previous == Status.INVALID and do_loop:
                    self.emit_wake_up()
                    return Status.RUNNING
            elif child_status == Status.FAILURE:
                self.repeat_count = 0
                self.reset_child()
                return Status.FAILURE
            else:
                return child_status
        self.repeat_count = 0
        return Status.SUCCESS

    def halt(self) -> None:
        self.repeat_count = 0
        super().halt()


class RetryUntilSuccessful(DecoratorNode):
    """BT.CPP ``RetryUntilSuccessful``."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, num_attempts: PortValue | int) -> None:
        super().__init__(name, child)
        self.num_attempts = num_attempts
        self.try_count = 0

    def execute(self) -> TickGenerator:
        attempts = _read(self.num_attempts)
        do_loop = self.try_count < attempts or attempts == -1
        self.status = Status.RUNNING
        while do_loop:
            previous = self.decorated.status
            child_status = yield from self.tick_child()
            if child_status == Status.SUCCESS:
                self.try_count = 0
                self.reset_child()
                return Status.SUCCESS
            if child_status == Status.FAILURE:
                self.try_count += 1
                do_loop = self.try_count < attempts or attempts == -1
                self.reset_child()
                if self.requires_wake_up() and previous == Status.INVALID and do_loop:
                    self.emit_wake_up()
                    return Status.RUNNING
            else:
                return child_status
        self.try_count = 0
        return Status.FAILURE

    def halt(self) -> None:
        self.try_count = 0
        super().halt()
