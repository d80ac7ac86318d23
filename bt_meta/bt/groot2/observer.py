"""Every status change of a py_trees tree, as BehaviorTree.CPP's status-change signal reports it.

BehaviorTree.CPP notifies its loggers from ``setStatus``/``resetStatus`` whenever a node's status changes,
including the quiet reset to IDLE a parent does when it finishes -- a status read after the tick would miss those
(a child that ran and was reset looks untouched). py_trees assigns ``behaviour.status`` directly, so the observer
puts a ``status`` property on each observed behaviour: every assignment that changes what BehaviorTree.CPP would
show is reported with BehaviorTree.CPP's status numbers, the node's uid and a wall-clock timestamp, in the order
it happened. The same subclass runs Groot2's hooks (:mod:`~bt_meta.bt.groot2.hooks`) around each node's tick.

The property lives in a subclass made per behaviour class, named like the original; :meth:`StatusObserver.close`
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
_OBSERVED: dict[type, type] = {}
_LOCK = threading.Lock()


def now_usec() -> int:
    return time.time_ns() // 1000


def _observed_class(cls: type) -> type:
    """A subclass of ``cls`` whose ``status`` attribute reports changes to ``self._groot2_observer``."""
    with _LOCK:
        made = _OBSERVED.get(cls)
        if made is not None:
            return made

        def get_status(self: Any) -> Any:
            return self.__dict__.get("status")

        def set_status(self: Any, value: Any) -> None:
            self.__dict__["status"] = value
            observer = self.__dict__.get("_groot2_observer")
            if observer is not None:
                observer.assigned(self, value)

        original_tick = cls.tick

        def tick(self: Any) -> Any:
            observer = self.__dict__.get("_groot2_observer")
            hooks = observer.hooks if observer is not None else None
            if not hooks:
                return (yield from original_tick(self))
            uid = observer.uid_of(self)
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

        made = type(cls.__name__, (cls,), {
            "status": property(get_status, set_status),
            "tick": tick,
            "__module__": cls.__module__,
            "__qualname__": cls.__qualname__,
            "_groot2_original_class": cls,
        })
        _OBSERVED[cls] = made
        return made


class StatusObserver:
    """Reports status changes of a published tree's nodes to subscribers, in tick order."""

    def __init__(self, tree: PublishedTree, clock: Callable[[], int] = now_usec) -> None:
        self.tree = tree
        self.clock = clock
        self._subscribers: list[Callback] = []
        # Groot2's breakpoints and replacements, consulted around every observed node's tick (set by the server).
        self.hooks: HookTable | None = None
        self._uids: dict[int, int] = {}
        # The status BehaviorTree.CPP would hold per uid: py_trees' own, except for the root reset after a tick.
        self._shown: dict[int, NodeStatus] = {}
        self._attached: list[py_trees.behaviour.Behaviour] = []
        for node in tree.nodes:
            self._attach(node.behaviour, node.uid)

    def _attach(self, behaviour: py_trees.behaviour.Behaviour, uid: int) -> None:
        if "_groot2_observer" in behaviour.__dict__:
            raise ValueError(f"behaviour {behaviour.name!r} is already observed")
        behaviour.__class__ = _observed_class(type(behaviour))
        behaviour.__dict__["_groot2_observer"] = self
        self._uids[id(behaviour)] = uid
        self._shown[uid] = status_code(behaviour.__dict__.get("status"))
        self._attached.append(behaviour)

    def uid_of(self, behaviour: py_trees.behaviour.Behaviour) -> int:
        return self._uids[id(behaviour)]

    def subscribe(self, callback: Callback) -> None:
        self._subscribers.append(callback)

    def assigned(self, behaviour: py_trees.behaviour.Behaviour, value: Any) -> None:
        """``behaviour.status = value`` happened: report it if it changes what BehaviorTree.CPP would show."""
        self._report(self._uids[id(behaviour)], status_code(value))

    def _report(self, uid: int, after: NodeStatus) -> None:
        before = self._shown[uid]
        if before == after:
            return
        self._shown[uid] = after
        stamp = self.clock()
        for callback in list(self._subscribers):
            callback(stamp, uid, before, after)

    def tick_finished(self, status: Any) -> None:
        """BehaviorTree.CPP's ``Tree::tickRoot`` resets a root that finished: report the root going back to IDLE.

        py_trees' root keeps its SUCCESS/FAILURE (bt-meta reads it); only what Groot2 is told changes.
        """
        if status_code(status) in (NodeStatus.SUCCESS, NodeStatus.FAILURE):
            self._report(self.tree.root.uid, NodeStatus.IDLE)

    def close(self) -> None:
        """Stop observing and give every behaviour its own class back."""
        for behaviour in self._attached:
            behaviour.__dict__.pop("_groot2_observer", None)
            original = getattr(type(behaviour), "_groot2_original_class", None)
            if original is not None:
                behaviour.__class__ = original
        self._attached.clear()
        self._subscribers.clear()

    def __enter__(self) -> StatusObserver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
