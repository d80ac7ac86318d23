"""Ticking a whole tree the way BehaviorTree.CPP's ``Tree`` does.

Offers:

* :func:`install_wake_up` -- give every BT.CPP node of a tree one shared :class:`WakeUpSignal` (BT.CPP's
  ``Tree::initialize``); returns it
* :func:`tick_exactly_once` -- one root tick (``Tree::tickExactlyOnce``)
* :func:`tick_once` -- a root tick, repeated while the root is RUNNING and a node raised the wake-up signal
  (``Tree::tickOnce``)
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import WakeUpSignal


def install_wake_up(root: py_trees.behaviour.Behaviour, signal: WakeUpSignal | None = None) -> WakeUpSignal:
    signal = signal or WakeUpSignal()
    for node in root.iterate():
        if hasattr(node, "wake_up"):
            node.wake_up = signal
    root.bt_wake_up = signal
    return signal


def tick_exactly_once(root: py_trees.behaviour.Behaviour) -> Status:
    root.tick_once()
    return root.status


def tick_once(root: py_trees.behaviour.Behaviour) -> Status:
    signal: WakeUpSignal | None = getattr(root, "bt_wake_up", None)
    # Like BT.CPP, a signal left pending by an earlier tick is not cleared first: it causes one re-tick.
    root.tick_once()
    while root.status == Status.RUNNING and signal is not None and signal.consume():
        root.tick_once()
    return root.status
