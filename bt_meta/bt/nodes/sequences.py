"""BehaviorTree.CPP's three sequences.

Offers:

* :class:`Sequence` -- resumes at the RUNNING child; on FAILURE resets every child and restarts at 0 next time
* :class:`SequenceWithMemory` -- resumes at the RUNNING child and, after a FAILURE, at the child that failed
  (BT.CPP keeps the index even when halted); inside a tree with a wake-up signal it ends the tick with RUNNING
  after each child that finished synchronously (BT.CPP 4.8 does, see :mod:`bt_meta.bt.nodes.loops`)
* :class:`ReactiveSequence` -- re-ticks every child from 0 on every tick; a RUNNING child halts all the others
* :class:`AsyncSequence` -- a Sequence that yields (RUNNING, wake-up) after each child that finished synchronously

py_trees' ``Sequence(memory=True)`` resumes at the RUNNING child but restarts at 0 after a failure, like BT.CPP's
``Sequence``; ``Sequence(memory=False)`` is close to ``ReactiveSequence`` but neither resets finished siblings nor
halts earlier RUNNING ones the same way, so these classes re-implement BT.CPP's ``tick()`` and ``halt()``.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes._ordered import ReactiveControl, ResumingControl
from bt_meta.bt.nodes.base import SKIPPED, ControlNode, TickGenerator


class Sequence(ResumingControl):
    """BT.CPP ``Sequence``."""

    stop_on = Status.FAILURE
    exhausted = Status.SUCCESS

    def __init__(self, name: str = "Sequence", children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
        super().__init__(name, children)


class SequenceWithMemory(ControlNode):
    """BT.CPP ``SequenceWithMemory``: a failed child is retried first next time, even after a halt."""

    def __init__(
        self, name: str = "SequenceWithMemory", children: list[py_trees.behaviour.Behaviour] | None = None
    ) -> None:
        super().__init__(name, children)
        self.current_child_idx = 0
        self.skipped_count = 0

    def execute(self) -> TickGenerator:
        if self.status != Status.RUNNING:
            self.skipped_count = 0
        self.status = Status.RUNNING
        while self.current_child_idx < len(self.children):
            previous = self.children[self.current_child_idx].status
            child_status = yield from self.tick_child(self.current_child_idx)
            if child_status == Status.RUNNING:
                return Status.RUNNING
            if child_status == Status.FAILURE:
                self.reset_children(self.current_child_idx)
                return Status.FAILURE
            self.current_child_idx += 1
            if child_status is SKIPPED:
                self.skipped_count += 1
                continue
            # BT.CPP 4.8 yields after a child that finished synchronously, whether or not it is async.
            if self.requires_wake_up() and previous == Status.INVALID and self.current_child_idx < len(self.children):
                self.emit_wake_up()
                return Status.RUNNING
        all_skipped = self.skipped_count == len(self.children)
        self.reset_children()
        self.current_child_idx = 0
        self.skipped_count = 0
        return SKIPPED if all_skipped else Status.SUCCESS


class ReactiveSequence(ReactiveControl):
    """BT.CPP ``ReactiveSequence``."""

    stop_on = Status.FAILURE
    exhausted = Status.SUCCESS

    def __init__(
        self, name: str = "ReactiveSequence", children: list[py_trees.behaviour.Behaviour] | None = None
    ) -> None:
        super().__init__(name, children)


class AsyncSequence(Sequence):
    """BT.CPP ``AsyncSequence``: a Sequence that ends the tick after each child that finished synchronously."""

    asynchronous = True

    def __init__(self, name: str = "AsyncSequence", children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
        super().__init__(name, children)
