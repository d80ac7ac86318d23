"""BehaviorTree.CPP decorators that rewrite their child's status.

Offers:

* :class:`Inverter` -- SUCCESS <-> FAILURE, RUNNING passes
* :class:`ForceSuccess`, :class:`ForceFailure` -- any finished status becomes SUCCESS / FAILURE
* :class:`KeepRunningUntilFailure` -- a SUCCESS becomes RUNNING (the child restarts next tick)
* :class:`RunOnce` -- the child runs to completion once; then SKIPPED or its remembered status

Unlike py_trees' Inverter/FailureIsSuccess, these reset the finished child (BT.CPP ``resetChild``) so that it
starts afresh on the next tick.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import SKIPPED, DecoratorNode, PortValue, TickGenerator


class Inverter(DecoratorNode):
    """BT.CPP ``Inverter``."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name, child)

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        child_status = yield from self.tick_child()
        if child_status == Status.SUCCESS:
            self.reset_child()
            return Status.FAILURE
        if child_status == Status.FAILURE:
            self.reset_child()
            return Status.SUCCESS
        return child_status


class _Force(DecoratorNode):
    forced: Status = Status.SUCCESS

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name, child)

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        child_status = yield from self.tick_child()
        if child_status in (Status.SUCCESS, Status.FAILURE):
            self.reset_child()
            return self.forced
        return child_status


class ForceSuccess(_Force):
    """BT.CPP ``ForceSuccess``."""

    forced = Status.SUCCESS


class ForceFailure(_Force):
    """BT.CPP ``ForceFailure``."""

    forced = Status.FAILURE


class KeepRunningUntilFailure(DecoratorNode):
    """BT.CPP ``KeepRunningUntilFailure``."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name, child)

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        child_status = yield from self.tick_child()
        if child_status == Status.SUCCESS:
            self.reset_child()
            return Status.RUNNING
        if child_status == Status.FAILURE:
            self.reset_child()
            return Status.FAILURE
        # BT.CPP returns its own status (RUNNING) when the child is skipped.
        return Status.RUNNING


class RunOnce(DecoratorNode):
    """BT.CPP ``RunOnce``: ticks the child until it finishes once; afterwards SKIPPED (``then_skip``) or the status
    it finished with."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, then_skip: PortValue | bool = True) -> None:
        super().__init__(name, child)
        self.then_skip = then_skip
        self.already_ticked = False
        self.returned_status: Status = Status.INVALID

    def execute(self) -> TickGenerator:
        skip = self.then_skip.get() if isinstance(self.then_skip, PortValue) else self.then_skip
        if self.already_ticked:
            return SKIPPED if skip else self.returned_status
        self.status = Status.RUNNING
        child_status = yield from self.tick_child()
        if child_status in (Status.SUCCESS, Status.FAILURE):
            self.already_ticked = True
            self.returned_status = child_status  # type: ignore[assignment]
            self.reset_child()
        return child_status
