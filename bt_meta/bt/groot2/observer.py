"""Every status change of a py_trees tree, as BehaviorTree.CPP's status-change signal reports it.

BehaviorTree.CPP notifies its loggers from ``setStatus``/``resetStatus`` whenever a node's status changes,
including the quiet reset to IDLE a parent does when it finishes -- a status read after the tick would miss those
(a child that ran and was reset looks untouched). py_trees assigns ``behaviour.status`` directly, so the observer
gives each observed behaviour a subclass whose ``__setattr__`` watches ``status``: every assignment that changes
what BehaviorTree.CPP would show is reported with BehaviorTree.CPP's status numbers, the node's uid and a
wall-clock timestamp, in the order it happened. For nodes Groot2 puts a hook on, the subclass also runs the hooks
(:mod:`~bt_meta.bt.groot2.hooks`) around the node's tick.

The subclass is made once per behaviour class and named like the original; :meth:`StatusObserver.close`
restores the original classes (``type(b) is X`` checks hold again afterwards).

Offers:

* :class:`StatusObserver` -- ``StatusObserver(published_tree)``; :meth:`~StatusObserver.subscribe` a callback
  ``(timestamp_usec, uid, previous, new)``; :meth:`~StatusObserver.close`
* :func:`now_usec` -- microseconds since the epoch (BehaviorTree.CPP's absolute timestamps)
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import py_trees

from bt_meta.bt.groot2.hooks import POST, PRE, HookTable
from bt_meta.bt.groot2.protocol import NodeStatus, status_code
from bt_meta.bt.groot2.published_tree import PublishedTree

Callback = Callable[[int, int, NodeStatus, NodeStatus], None]
_TO_PY_TREES = {NodeStatus.SUCCESS: py_trees.common.Status.SUCCESS, NodeStatus.FAILURE: py_trees.common.Status.FAILURE}
_HOOKABLE = (py_trees.common.Status.INVALID, py_trees.common.Status.RUNNING)
_OBSERVED: dict[tuple[type, bool], type] = {}
_LOCK = threading.Lock()


def now_usec() -> int:
    return time.time_ns() // 1000


def _observed_class(cls: type, hooked: bool) -> type:
    """A subclass of ``cls`` whose ``status`` assignments are reported; ``hooked`` also runs Groot2's hooks.

    Only nodes Groot2 put a hook on get the hooked variant (an extra generator level per tick).
    """
    with _LOCK:
        made = _OBSERVED.get((cls, hooked))
        if made is not None:
            return made

        original_setattr = cls.__setattr__

        def setattr_observed(self: Any, name: str, value: Any) -> None:
            # Only writes pay (reads of ``status`` stay plain attribute reads, which bt-meta's nodes do a lot).
            if name != "status":
                original_setattr(self, name, value)
                return
            state = self.__dict__
            state["status"] = value
            shown = state.get("_groot2_shown", value)
            if value is not shown:  # re-assigning the same status costs one comparison
                state["_groot2_shown"] = value
                state["_groot2_observer"].changed(state["_groot2_uid"], shown, value)

        namespace: dict[str, Any] = {
            "__setattr__": setattr_observed,
            "__module__": cls.__module__,
            "__qualname__": cls.__qualname__,
            "_groot2_original_class": cls,
        }
        if hooked:
            original_tick = cls.tick

            def tick(self: Any) -> Any:
                observer = self.__dict__.get("_groot2_observer")
                hooks = observer.hooks if observer is not None else None
                if not hooks:
                    return (yield from original_tick(self))
                uid = self.__dict__["_groot2_uid"]
                replaced = hooks.run(PRE, uid) if self.__dict__.get("status") in _HOOKABLE else None
                if replaced is not None:  # Groot2 decided the result: the node itself does not tick
                    self.status = _TO_PY_TREES[replaced]
                    yield self
                else:
                    yield from original_tick(self)
                after = hooks.run(POST, uid)
                if after is not None:
                    self.status = _TO_PY_TREES[after]
                return None

            namespace["tick"] = tick
        made = type(cls.__name__, (cls,), namespace)
        _OBSERVED[(cls, hooked)] = made
        return made


class StatusObserver:
    """Reports status changes of a published tree's nodes to subscribers, in tick order."""

    def __init__(self, tree: PublishedTree, clock: Callable[[], int] = now_usec) -> None:
        self.tree = tree
        self.clock = clock
        self._subscribers: list[Callback] = []
        # Groot2's breakpoints and replacements, consulted around hooked nodes' ticks (set by the server).
        self.hooks: HookTable | None = None
        self._by_uid: dict[int, py_trees.behaviour.Behaviour] = {}
        for node in tree.nodes:
            self._attach(node.behaviour, node.uid)

    def _attach(self, behaviour: py_trees.behaviour.Behaviour, uid: int) -> None:
        if "_groot2_observer" in behaviour.__dict__:
            raise ValueError(f"behaviour {behaviour.name!r} is already observed")
        state = behaviour.__dict__
        # What BehaviorTree.CPP would show: py_trees' own status, except for the root reset after a tick.
        state["_groot2_shown"] = state.get("status")
        state["_groot2_uid"] = uid
        state["_groot2_observer"] = self
        behaviour.__class__ = _observed_class(type(behaviour), hooked=False)
        self._by_uid[uid] = behaviour

    def hook_node(self, uid: int) -> None:
        """Run Groot2's hooks around this node's tick from now on (called when a hook is inserted)."""
        behaviour = self._by_uid.get(uid)
        if behaviour is not None:
            original = type(behaviour)._groot2_original_class  # type: ignore[attr-defined]
            behaviour.__class__ = _observed_class(original, hooked=True)

    def subscribe(self, callback: Callback) -> None:
        self._subscribers.append(callback)

    def changed(self, uid: int, before: Any, after: Any) -> None:
        """A node's shown status changed from ``before`` to ``after`` (py_trees statuses): tell the subscribers."""
        old, new = status_code(before), status_code(after)
        if old == new:
            return
        stamp = self.clock()
        for callback in self._subscribers:
            callback(stamp, uid, old, new)

    def tick_finished(self, status: Any) -> None:
        """BehaviorTree.CPP's ``Tree::tickRoot`` resets a root that finished: report the root going back to IDLE.

        py_trees' root keeps its SUCCESS/FAILURE (bt-meta reads it); only what Groot2 is told changes.
        """
        if status_code(status) in (NodeStatus.SUCCESS, NodeStatus.FAILURE):
            root = self._by_uid[self.tree.root.uid]
            shown = root.__dict__["_groot2_shown"]
            root.__dict__["_groot2_shown"] = py_trees.common.Status.INVALID
            self.changed(self.tree.root.uid, shown, py_trees.common.Status.INVALID)

    def close(self) -> None:
        """Stop observing and give every behaviour its own class back."""
        for behaviour in self._by_uid.values():
            original = getattr(type(behaviour), "_groot2_original_class", None)
            if original is not None:
                behaviour.__class__ = original
            for key in ("_groot2_observer", "_groot2_shown", "_groot2_uid"):
                behaviour.__dict__.pop(key, None)
        self._by_uid.clear()
        self._subscribers.clear()

    def __enter__(self) -> StatusObserver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
