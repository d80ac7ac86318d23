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
from bt_meta.bt.nodes.status import Returned, returned


def install_wake_up(root: py_trees.behaviour.Behaviour, signal: WakeUpSignal | None = None) -> WakeUpSignal:
    signal = signal or WakeUpSignal()
    for node in root.iterate():
        if hasattr(node, "wake_up"):
            node.wake_up = signal
    root.bt_wake_up = signal
    return signal


def _finish(root: py_trees.behaviour.Behaviour) -> Returned:
    # BT.CPP's tickRoot resets a root that finished to IDLE; we keep its status readable and mark it as the root
    # instead, so that its pre-conditions treat a finished status as idle (see conditions.py).
    root.bt_root = True
    return returned(root)


def tick_exactly_once(root: py_trees.behaviour.Behaviour) -> Returned:
    root.tick_once()
    return _finish(root)


# tick_once re-ticks a woken root at most this many times: a Repeat num_cycles="-1" over a child that completes at
# once wakes it forever (BT.CPP spins there), and a caller's tick budget must still bound the run.
MAX_WAKE_UPS = 1_000


def tick_once(root: py_trees.behaviour.Behaviour) -> Returned:
    signal: WakeUpSignal | None = getattr(root, "bt_wake_up", None)
    # Like BT.CPP, a signal left pending by an earlier tick is not cleared first: it causes one re-tick.
    root.tick_once()
    wake_ups = 0
    while returned(root) == Status.RUNNING and signal is not None and wake_ups < MAX_WAKE_UPS and signal.consume():
        wake_ups += 1
        root.tick_once()
    return _finish(root)
