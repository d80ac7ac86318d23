"""BehaviorTree.CPP's ``Parallel``: N-of-M success and failure thresholds.

Offers:

* :class:`Parallel` -- ticks every child that has not finished yet; SUCCESS once ``success_count`` children
  succeeded, FAILURE once ``failure_count`` failed or success became impossible; negative counts mean
  "number of children + 1 + count" (``-1`` = all)
* :class:`ParallelAll` -- ticks every child to completion; FAILURE once ``max_failures`` failed
* :func:`threshold` -- that arithmetic

py_trees' ``Parallel`` only knows SuccessOnAll/SuccessOnOne/SuccessOnSelected and fails on the first failure, so it
cannot express BT.CPP's counts; this class re-implements BT.CPP's ``tick()``, including that finished children
are not ticked again until the parallel completes or is halted.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import SKIPPED, ControlNode, PortValue, TickGenerator
from bt_meta.bt.registry import PortSpec
from bt_meta.errors import BtMetaError

SUCCESS_COUNT = PortSpec("success_count", "input", "int", "-1", "children that must succeed (negative: all but n-1)")
FAILURE_COUNT = PortSpec("failure_count", "input", "int", "1", "children that must fail (negative: all but n-1)")


class ParallelThresholdError(BtMetaError):
    """A threshold larger than the number of children: BT.CPP throws the same at tick time."""


def threshold(count: int, children: int) -> int:
    return max(children + count + 1, 0) if count < 0 else count


class Parallel(ControlNode):
    """BT.CPP ``Parallel``."""

    def __init__(
        self,
        name: str = "Parallel",
        children: list[py_trees.behaviour.Behaviour] | None = None,
        success_count: PortValue | int = -1,
        failure_count: PortValue | int = 1,
    ) -> None:
        super().__init__(name, children)
        self.success_count = success_count
        self.failure_count = failure_count
        self.completed: set[int] = set()
        self.success_total = 0
        self.failure_total = 0

    def _read(self, value: PortValue | int) -> int:
        return value.get() if isinstance(value, PortValue) else value

    def thresholds(self) -> tuple[int, int]:
        count = len(self.children)
        self.raw_success = self._read(self.success_count)
        success = threshold(self.raw_success, count)
        failure = threshold(self._read(self.failure_count), count)
        if count < success:
            raise ParallelThresholdError(f"{self.name}: success_count {success} > {count} children, can never succeed")
        if count < failure:
            raise ParallelThresholdError(f"{self.name}: failure_count {failure} > {count} children, can never fail")
        return success, failure

    def clear(self) -> None:
        self.completed.clear()
        self.success_total = 0
        self.failure_total = 0

    def execute(self) -> TickGenerator:
        required_success, required_failure = self.thresholds()
        count = len(self.children)
        self.status = Status.RUNNING
        skipped = 0
        for index in range(count):
            if index not in self.completed:
                child_status = yield from self.tick_child(index)
                if child_status is SKIPPED:
                    skipped += 1
                elif child_status == Status.SUCCESS:
                    self.completed.add(index)
                    self.success_total += 1
                elif child_status == Status.FAILURE:
                    self.completed.add(index)
                    self.failure_total += 1
            if self.success_total >= required_success or (
                self.raw_success < 0 and self.success_total + skipped >= required_success
            ):
                self.clear()
                self.reset_children()
                return Status.SUCCESS
            if count - self.failure_total < required_success or self.failure_total == required_failure:
                self.clear()
                self.reset_children()
                return Status.FAILURE
        return SKIPPED if skipped == count else Status.RUNNING

    def halt(self) -> None:
        self.clear()
        super().halt()


class ParallelAll(ControlNode):
    """BT.CPP ``ParallelAll``: ticks every child until all finished; FAILURE when at least ``max_failures`` failed
    (negative: number of children + 1 + value)."""

    def __init__(
        self, name: str, children: list[py_trees.behaviour.Behaviour], max_failures: PortValue | int = 1
    ) -> None:
        super().__init__(name, children)
        self.max_failures = max_failures
        self.completed: set[int] = set()
        self.failure_total = 0

    def execute(self) -> TickGenerator:
        raw = self.max_failures.get() if isinstance(self.max_failures, PortValue) else self.max_failures
        count = len(self.children)
        failure_threshold = threshold(raw, count)
        if count < failure_threshold:
            raise ParallelThresholdError(f"{self.name}: max_failures {failure_threshold} > {count} children")
        self.status = Status.RUNNING
        skipped = 0
        for index in range(count):
            if index in self.completed:
                continue
            child_status = yield from self.tick_child(index)
            if child_status is SKIPPED:
                skipped += 1
            elif child_status == Status.SUCCESS:
                self.completed.add(index)
            elif child_status == Status.FAILURE:
                self.completed.add(index)
                self.failure_total += 1
        if skipped == count:
            return SKIPPED
        if skipped + len(self.completed) >= count:
            self.reset_children()
            self.completed.clear()
            status = Status.FAILURE if self.failure_total >= failure_threshold else Status.SUCCESS
            self.failure_total = 0
            return status
        return Status.RUNNING

    def halt(self) -> None:
        self.completed.clear()
        self.failure_total = 0
        super().halt()
