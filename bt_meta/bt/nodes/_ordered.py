"""The two tick loops BehaviorTree.CPP's Sequence/Fallback pairs share, with the stopping status as a parameter.

A Sequence is a Fallback with SUCCESS and FAILURE swapped (BT.CPP's ``SequenceNode`` and ``FallbackNode`` are
written that way too); the subclasses only say which child status ends the tick early.

Offers:

* :class:`ResumingControl` -- resumes at the RUNNING child; the stopping status resets every child and restarts
  at 0 next time (``Sequence``, ``Fallback``)
* :class:`ReactiveControl` -- re-ticks every child from 0 on every tick; a RUNNING child halts all the others
  (``ReactiveSequence``, ``ReactiveFallback``)
"""

from __future__ import annotations

from typing import ClassVar

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import SKIPPED, ControlNode, TickGenerator


class ResumingControl(ControlNode):
    """Ticks children in order from ``current_child_idx``; ``stop_on`` ends the tick, all others give ``exhausted``."""

    stop_on: ClassVar[Status]
    exhausted: ClassVar[Status]
    # AsyncSequence / AsyncFallback: end the tick (RUNNING, wake-up raised) after a child that finished synchronously.
    asynchronous: ClassVar[bool] = False

    def __init__(self, name: str, children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
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
            if child_status == self.stop_on:
                self.reset_children()
                self.current_child_idx = 0
                return self.stop_on
            if child_status is SKIPPED:
                self.skipped_count += 1
            self.current_child_idx += 1
            if (
                self.asynchronous
                and child_status is not SKIPPED
                and self.requires_wake_up()
                and previous == Status.INVALID
                and self.current_child_idx < len(self.children)
            ):
                self.emit_wake_up()
                return Status.RUNNING
        all_skipped = self.skipped_count == len(self.children)
        self.reset_children()
        self.current_child_idx = 0
        self.skipped_count = 0
        return SKIPPED if all_skipped else self.exhausted

    def halt(self) -> None:
        self.current_child_idx = 0
        self.skipped_count = 0
        super().halt()


class ReactiveControl(ControlNode):
    """Ticks every child from 0 each tick; ``stop_on`` ends the tick, all others give ``exhausted``."""

    stop_on: ClassVar[Status]
    exhausted: ClassVar[Status]

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        all_skipped = True
        for index in range(len(self.children)):
            child_status = yield from self.tick_child(index)
            all_skipped = all_skipped and child_status is SKIPPED
            if child_status is SKIPPED:
                self.reset_child(index)  # BT.CPP: so that it can be skipped again
                continue
            if child_status == Status.RUNNING:
                for other in range(len(self.children)):
                    if other != index:
                        self.reset_child(other)
                return Status.RUNNING
            if child_status == self.stop_on:
                self.reset_children()
                return self.stop_on
        self.reset_children()
        return SKIPPED if all_skipped else self.exhausted
