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

from typing import ClassVar

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import SKIPPED, DecoratorNode, PortValue, TickGenerator


def _read(value: PortValue | int) -> int:
    return value.get() if isinstance(value, PortValue) else value


class _CountedLoop(DecoratorNode):
    """Repeat and RetryUntilSuccessful are one loop with SUCCESS and FAILURE swapped: ``loops_on`` counts a cycle
    and ticks again (returned when the count is used up), the other finished status ends the loop at once."""

    loops_on: ClassVar[Status]
    ends_on: ClassVar[Status]

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name, child)
        self.count = 0

    def limit(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def execute(self) -> TickGenerator:
        limit = self.limit()
        do_loop = self.count < limit or limit == -1
        self.status = Status.RUNNING
        while do_loop:
            previous = self.decorated.status
            child_status = yield from self.tick_child()
            if child_status == self.loops_on:
                self.count += 1
                do_loop = self.count < limit or limit == -1
                self.reset_child()
                if self.requires_wake_up() and previous == Status.INVALID and do_loop:
                    self.emit_wake_up()
                    return Status.RUNNING
            elif child_status is SKIPPED:
                self.reset_child()  # BT.CPP: skipped again next time; the count is kept
                return SKIPPED
            elif child_status == self.ends_on:
                self.count = 0
                self.reset_child()
                return self.ends_on
            else:
                return child_status
        self.count = 0
        return self.loops_on

    def halt(self) -> None:
        self.count = 0
        super().halt()


class Repeat(_CountedLoop):
    """BT.CPP ``Repeat``."""

    loops_on = Status.SUCCESS
    ends_on = Status.FAILURE

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, num_cycles: PortValue | int) -> None:
        super().__init__(name, child)
        self.num_cycles = num_cycles

    def limit(self) -> int:
        return _read(self.num_cycles)


class RetryUntilSuccessful(_CountedLoop):
    """BT.CPP ``RetryUntilSuccessful``."""

    loops_on = Status.FAILURE
    ends_on = Status.SUCCESS

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, num_attempts: PortValue | int) -> None:
        super().__init__(name, child)
        self.num_attempts = num_attempts

    def limit(self) -> int:
        return _read(self.num_attempts)
