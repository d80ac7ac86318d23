"""BehaviorTree.CPP's looping decorators.

Offers:

* :class:`Repeat` -- ticks its child until it succeeded ``num_cycles`` times (``-1``: forever); a FAILURE stops
* :class:`RetryUntilSuccessful` -- ticks its child until it succeeds, at most ``num_attempts`` times (``-1``: forever)
* :class:`LoopQueue` -- LoopInt/LoopDouble/LoopBool/LoopString: one queue item per tick into ``value``
* :func:`parse_queue` -- ``"1;2;3"`` -> a deque of typed items

Both loop *within one tick* while the child keeps finishing, exactly like BT.CPP, with BT.CPP's exception: inside
a tree with a wake-up signal (every tree BT.CPP builds, and every tree our XML reader builds) a child that
finished *synchronously* (it was idle when ticked) ends the tick with RUNNING and raises the signal, so that
``tick_once`` re-ticks the root and ``tick_exactly_once`` makes one iteration per tick. py_trees' Repeat/Retry
always take one iteration per tick and count differently, so these classes re-implement BT.CPP's ``tick()``.
"""

from __future__ import annotations

from collections import deque
from typing import Any, ClassVar

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes import entries
from bt_meta.bt.nodes.base import SKIPPED, DecoratorNode, PortValue, TickGenerator
from bt_meta.bt.nodes.status import parse_status

# A child that keeps completing while the loop runs (it was RUNNING, so BT.CPP does not yield) ends the tick after
# this many cycles: RUNNING, with the wake-up signal raised, so ``--ticks`` bounds a ``-1`` or huge count. BT.CPP
# would spin inside the tick; no finite run can observe the difference.
MAX_CYCLES_PER_TICK = 1000


def _read(value: PortValue | int) -> int:
    return value.get() if isinstance(value, PortValue) else value


class _CountedLoop(DecoratorNode):
    """Repeat and RetryUntilSuccessful are one loop with SUCCESS and FAILURE swapped: ``loops_on`` counts a cycle
    and ticks again (returned when the count is used up), the other finished status ends the loop at once."""

    loops_on: ClassVar[Status]
    ends_on: ClassVar[Status]

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name, child)
        self.count = 0

    def limit(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def execute(self) -> TickGenerator:
        limit = self.limit()
        do_loop = self.count < limit or limit == -1
        self.status = Status.RUNNING
        cycles = 0
        while do_loop:
            cycles += 1
            if cycles > MAX_CYCLES_PER_TICK:
                self.emit_wake_up()
                return Status.RUNNING
            previous = self.decorated.status
            child_status = yield from self.tick_child()
            if child_status == self.loops_on:
                self.count += 1
                do_loop = self.count < limit or limit == -1
                self.reset_child()
                if self.requires_wake_up() and previous == Status.INVALID and do_loop:
                    self.emit_wake_up()
                    return Status.RUNNING
            elif child_status is SKIPPED:
                self.reset_child()  # BT.CPP: skipped again next time; the count is kept
                return SKIPPED
            elif child_status == self.ends_on:
                self.count = 0
                self.reset_child()
                return self.ends_on
            else:
                return child_status
        self.count = 0
        return self.loops_on

    def halt(self) -> None:
        self.count = 0
        super().halt()


class Repeat(_CountedLoop):
    """BT.CPP ``Repeat``."""

    loops_on = Status.SUCCESS
    ends_on = Status.FAILURE

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, num_cycles: PortValue | int) -> None:
        super().__init__(name, child)
        self.num_cycles = num_cycles

    def limit(self) -> int:
        return _read(self.num_cycles)


class RetryUntilSuccessful(_CountedLoop):
    """BT.CPP ``RetryUntilSuccessful``."""

    loops_on = Status.FAILURE
    ends_on = Status.SUCCESS

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, num_attempts: PortValue | int) -> None:
        super().__init__(name, child)
        self.num_attempts = num_attempts

    def limit(self) -> int:
        return _read(self.num_attempts)


def _convert_item(text: str, item_type: str) -> Any:
    text = text.strip()
    if item_type == "int":
        return int(text, 10)
    if item_type == "double":
        return float(text)
    if item_type == "bool":
        lowered = text.lower()
        if lowered in ("true", "1"):
            return True
        if lowered in ("false", "0"):
            return False
        raise ValueError(f"expected true or false, got {text!r}")
    return text


def parse_queue(text: str, item_type: str) -> deque[Any]:
    """BT.CPP's queue literal: items separated by ``;``."""
    return deque(_convert_item(part, item_type) for part in text.split(";") if part != "" or item_type == "string")


class LoopQueue(DecoratorNode):
    """BT.CPP ``LoopInt`` / ``LoopDouble`` / ``LoopBool`` / ``LoopString``: pops one item of ``queue`` into
    ``value`` and ticks the child, once per tick (RUNNING) until the queue is empty (then ``if_empty``); a FAILURE
    of the child ends the loop. A literal queue restarts full each time the node starts; a ``{key}`` queue is
    shared and consumed."""

    def __init__(
        self,
        name: str,
        child: py_trees.behaviour.Behaviour,
        queue: PortValue,
        value: PortValue,
        if_empty: Any,
        item_type: str,
    ) -> None:
        super().__init__(name, child)
        self.queue = queue
        self.value = value
        self.if_empty = if_empty
        self.item_type = item_type
        self.static_queue = parse_queue(queue.text or "", item_type) if queue.key is None else None
        self.current: deque[Any] | None = None
        self.child_running = False

    def shared_queue(self) -> deque[Any] | None:
        if self.queue.key is None or not entries.exists(self.queue.key):
            return None
        current = entries.read(self.queue.key)
        if isinstance(current, str):
            current = parse_queue(current, self.item_type)
            entries.write(self.queue.key, current)
        elif isinstance(current, list):
            current = deque(current)
            entries.write(self.queue.key, current)
        return current if isinstance(current, deque) else None

    def execute(self) -> TickGenerator:
        popped = False
        if self.status == Status.INVALID:
            self.child_running = False
            if self.static_queue is not None:
                self.current = deque(self.static_queue)
        if not self.child_running:
            if self.static_queue is None:
                self.current = self.shared_queue()
            if self.current:
                item = self.current.popleft()
                popped = True
                self.value.set(item)
        if not popped and not self.child_running:
            otherwise = self.if_empty.get() if isinstance(self.if_empty, PortValue) else self.if_empty
            return parse_status(otherwise) if isinstance(otherwise, str) else otherwise
        if self.status == Status.INVALID:
            self.status = Status.RUNNING
        child_status = yield from self.tick_child()
        self.child_running = child_status == Status.RUNNING
        if child_status in (Status.SUCCESS, Status.FAILURE):
            self.reset_child()
        if child_status == Status.FAILURE:
            return Status.FAILURE
        return Status.RUNNING
