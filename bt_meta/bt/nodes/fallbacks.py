"""BehaviorTree.CPP's fallbacks (selectors).

Offers:

* :class:`Fallback` -- resumes at the RUNNING child; a SUCCESS resets every child and restarts at 0 next time
* :class:`ReactiveFallback` -- re-ticks every child from 0 on every tick; a RUNNING child halts all the others

py_trees' ``Selector(memory=False)`` halts lower-priority RUNNING children like ``ReactiveFallback`` but does not
reset the failed higher-priority ones, and ``Selector(memory=True)`` matches ``Fallback`` only for leaves; these
classes re-implement BT.CPP's ``tick()`` and ``halt()``.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import ControlNode, TickGenerator


class Fallback(ControlNode):
    """BT.CPP ``Fallback``."""

    def __init__(self, name: str = "Fallback", children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
        super().__init__(name, children)
        self.current_child_idx = 0

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        while self.current_child_idx < len(self.children):
            child_status = yield from self.tick_child(self.current_child_idx)
            if child_status == Status.RUNNING:
                return Status.RUNNING
            if child_status == Status.SUCCESS:
                self.reset_children()
                self.current_child_idx = 0
                return Status.SUCCESS
            self.current_child_idx += 1
        self.reset_children()
        self.current_child_idx = 0
        return Status.FAILURE

    def halt(self) -> None:
        self.current_child_idx = 0
        super().halt()


class ReactiveFallback(ControlNode):
    """BT.CPP ``ReactiveFallback``."""

    def __init__(
        self, name: str = "ReactiveFallback", children: list[py_trees.behaviour.Behaviour] | None = None
    ) -> None:
        super().__init__(name, children)

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        for index in range(len(self.children)):
            child_status = yield from self.tick_child(index)
            if child_status == Status.RUNNING:
                for other in range(len(self.children)):
                    if other != index:
                        self.reset_child(other)
                return Status.RUNNING
            if child_status == Status.SUCCESS:
                self.reset_children()
                return Status.SUCCESS
        self.reset_children()
        return Status.FAILURE
