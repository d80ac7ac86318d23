"""BehaviorTree.CPP's built-in leaves.

Offers:

* :class:`AlwaysSuccess`, :class:`AlwaysFailure` -- constant actions
* :class:`SetBlackboard` -- copies ``value`` (a literal or another ``{key}``) to ``output_key``; SUCCESS
* :class:`UnsetBlackboard` -- removes an entry; SUCCESS
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes import entries
from bt_meta.bt.nodes.base import PortValue, absolute_key
from bt_meta.bt.registry import blackboard_key


class AlwaysSuccess(py_trees.behaviour.Behaviour):
    """BT.CPP ``AlwaysSuccess``."""

    def __init__(self, name: str = "AlwaysSuccess") -> None:
        super().__init__(name)

    def update(self) -> Status:
        return Status.SUCCESS


class AlwaysFailure(py_trees.behaviour.Behaviour):
    """BT.CPP ``AlwaysFailure``."""

    def __init__(self, name: str = "AlwaysFailure") -> None:
        super().__init__(name)

    def update(self) -> Status:
        return Status.FAILURE


class SetBlackboard(py_trees.behaviour.Behaviour):
    """BT.CPP ``SetBlackboard``: ``output_key`` names the entry (with or without braces), ``value`` is copied."""

    def __init__(self, name: str, value: PortValue, output_key: str) -> None:
        super().__init__(name)
        self.value = value
        self.output_key = absolute_key(blackboard_key(output_key) or output_key)

    def update(self) -> Status:
        value = self.value.get() if self.value.key is not None else self.value.text
        entries.write(self.output_key, value)
        return Status.SUCCESS


class UnsetBlackboard(py_trees.behaviour.Behaviour):
    """BT.CPP ``UnsetBlackboard``: removes the entry ``key`` (a root key, already mapped by the loader); SUCCESS."""

    def __init__(self, name: str, key: str) -> None:
        super().__init__(name)
        self.key = absolute_key(blackboard_key(key) or key)

    def update(self) -> Status:
        entries.unset(self.key)
        return Status.SUCCESS
