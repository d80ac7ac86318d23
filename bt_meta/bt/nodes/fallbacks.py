"""BehaviorTree.CPP's fallbacks (selectors).

Offers:

* :class:`Fallback` -- resumes at the RUNNING child; a SUCCESS resets every child and restarts at 0 next time
* :class:`ReactiveFallback` -- re-ticks every child from 0 on every tick; a RUNNING child halts all the others
* :class:`AsyncFallback` -- a Fallback that yields (RUNNING, wake-up) after each child that failed synchronously

py_trees' ``Selector(memory=False)`` halts lower-priority RUNNING children like ``ReactiveFallback`` but does not
reset the failed higher-priority ones, and ``Selector(memory=True)`` matches ``Fallback`` only for leaves; these
classes re-implement BT.CPP's ``tick()`` and ``halt()``.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes._ordered import ReactiveControl, ResumingControl


class Fallback(ResumingControl):
    """BT.CPP ``Fallback``."""

    stop_on = Status.SUCCESS
    exhausted = Status.FAILURE

    def __init__(self, name: str = "Fallback", children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
        super().__init__(name, children)


class ReactiveFallback(ReactiveControl):
    """BT.CPP ``ReactiveFallback``."""

    stop_on = Status.SUCCESS
    exhausted = Status.FAILURE

    def __init__(
        self, name: str = "ReactiveFallback", children: list[py_trees.behaviour.Behaviour] | None = None
    ) -> None:
        super().__init__(name, children)


class AsyncFallback(Fallback):
    """BT.CPP ``AsyncFallback``: a Fallback that ends the tick after each child that failed synchronously."""

    asynchronous = True

    def __init__(self, name: str = "AsyncFallback", children: list[py_trees.behaviour.Behaviour] | None = None) -> None:
        super().__init__(name, children)
