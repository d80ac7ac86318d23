"""BehaviorTree.CPP's ``SubTree`` node.

Offers:

* :class:`SubTree` -- passes its subtree's status through and resets the subtree when it finishes

The subtree's own blackboard scope is implemented by the XML reader, which rewrites every ``{key}`` inside the
subtree to the parent's key (remapped or ``_autoremap``-ed ports) or to a key private to this SubTree instance.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes import entries
from bt_meta.bt.nodes.base import DecoratorNode, TickGenerator


class SubTree(DecoratorNode):
    """BT.CPP ``SubTree``; ``tree_id`` is the ``<BehaviorTree ID>`` it instantiates."""

    def __init__(
        self,
        name: str,
        child: py_trees.behaviour.Behaviour,
        tree_id: str,
        init: dict[str, str] | None = None,
        scope: str = "",
    ) -> None:
        super().__init__(name, child)
        self.tree_id = tree_id
        # The blackboard prefix of this instance's private entries (the reader's ``/_<TreeID>_<n>``); Groot2's
        # blackboard view uses it to tell this subtree's entries from the others.
        self.scope = scope
        # Literal remappings (``<SubTree ID="X" speed="3"/>``) written into the private scope once, before the first
        # tick (BT.CPP writes them when the tree is created; nothing else can write a private entry before that).
        self.init_values = dict(init or {})
        self._initialised = False

    def initialise(self) -> None:
        if not self._initialised:
            self._initialised = True
            for key, value in self.init_values.items():
                entries.write(key, value)

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        child_status = yield from self.tick_child()
        if child_status in (Status.SUCCESS, Status.FAILURE):
            self.reset_child()
        return child_status
