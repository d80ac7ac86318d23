"""BehaviorTree.CPP's nodes that watch a blackboard entry for writes (see :mod:`bt_meta.bt.nodes.entries`).

Offers:

* :class:`WasEntryUpdated` -- SUCCESS when the entry was written since this node last looked, else FAILURE
* :class:`EntryUpdatedDecorator` -- ``SkipUnlessUpdated`` (returns SKIPPED) and ``WaitValueUpdate`` (returns
  RUNNING) when the entry was not written since the last look; otherwise ticks its child until it finishes
"""

from __future__ import annotations

from collections.abc import Iterator

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes import entries
from bt_meta.bt.nodes.base import DecoratorNode, TickGenerator
from bt_meta.bt.nodes.status import Returned, returned


class _Watch:
    def __init__(self, key: str) -> None:
        self.key = key
        self.seen = 0

    def updated(self) -> bool | None:
        """``None`` when the entry does not exist; otherwise whether it was written since the last call."""
        current = entries.sequence_id(self.key)
        if current is None:
            return None
        previous, self.seen = self.seen, current
        return previous != current


class WasEntryUpdated(py_trees.behaviour.Behaviour):
    """BT.CPP ``WasEntryUpdated``."""

    def __init__(self, name: str, key: str) -> None:
        super().__init__(name)
        self.watch = _Watch(key)

    def update(self) -> Status:
        return Status.SUCCESS if self.watch.updated() else Status.FAILURE


class EntryUpdatedDecorator(DecoratorNode):
    """BT.CPP ``SkipUnlessUpdated`` / ``WaitValueUpdate``."""

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, key: str, if_not_updated: Returned) -> None:
        super().__init__(name, child)
        self.watch = _Watch(key)
        self.if_not_updated = if_not_updated
        self.still_executing_child = False

    def execute(self) -> TickGenerator:
        if not self.still_executing_child and not self.watch.updated():
            return self.if_not_updated
        yield from self.decorated.tick()
        status = returned(self.decorated)
        self.still_executing_child = status == Status.RUNNING
        return status

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        for behaviour in super().tick():
            if behaviour is self and self.decorated.status in (Status.SUCCESS, Status.FAILURE):
                # BT.CPP's DecoratorNode::executeTick resets a finished child after this node's status is set
                # (Groot2 and .btlog see the child go IDLE after its parent finished, not before).
                self.reset_child()
            yield behaviour

    def halt(self) -> None:
        # BT.CPP's halt() here does not halt the child (only the flag is cleared).
        self.still_executing_child = False
