"""BehaviorTree.CPP's branching controls.

Offers:

* :class:`IfThenElse` -- ticks child 0; SUCCESS -> child 1, FAILURE -> child 2 (FAILURE when there is none); the
  condition is not re-ticked while the chosen branch is RUNNING
* :class:`WhileDoElse` -- re-ticks child 0 on every tick and halts the branch it did not choose
* :class:`Switch` -- ``Switch2`` ... ``Switch6``: the child whose ``case_N`` equals ``variable`` (as a string, an
  integer, a real or an enum), else the last (default) child
* :func:`switch_matches` -- that equality
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import SKIPPED, ControlNode, PortValue, TickGenerator
from bt_meta.bt.nodes.entries import BlackboardEnvironment
from bt_meta.bt.script.values import to_string
from bt_meta.errors import BtMetaError


class BranchError(BtMetaError):
    """A state BT.CPP throws on at tick time (a condition child that was skipped)."""


class IfThenElse(ControlNode):
    """BT.CPP ``IfThenElse``."""

    def __init__(self, name: str, children: list[py_trees.behaviour.Behaviour]) -> None:
        super().__init__(name, children)
        self.child_idx = 0

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        if self.child_idx == 0:
            condition = yield from self.tick_child(0)
            if condition == Status.RUNNING:
                return Status.RUNNING
            if condition == Status.SUCCESS:
                self.child_idx = 1
            elif condition == Status.FAILURE:
                if len(self.children) == 3:
                    self.child_idx = 2
                else:
                    return Status.FAILURE
        if self.child_idx == 0:
            raise BranchError(f"{self.name}: the condition of IfThenElse was skipped")
        status = yield from self.tick_child(self.child_idx)
        if status == Status.RUNNING:
            return Status.RUNNING
        self.reset_children()
        self.child_idx = 0
        return status

    def halt(self) -> None:
        self.child_idx = 0
        super().halt()


class WhileDoElse(ControlNode):
    """BT.CPP ``WhileDoElse``."""

    def execute(self) -> TickGenerator:
        self.status = Status.RUNNING
        condition = yield from self.tick_child(0)
        if condition == Status.RUNNING:
            return Status.RUNNING
        three = len(self.children) == 3
        if condition == Status.SUCCESS:
            if three:
                self.reset_child(2)
            status = yield from self.tick_child(1)
        elif condition == Status.FAILURE:
            if three:
                self.reset_child(1)
                status = yield from self.tick_child(2)
            else:
                status = Status.FAILURE
        else:
            raise BranchError(f"{self.name}: the condition of WhileDoElse was skipped")
        if status == Status.RUNNING:
            return Status.RUNNING
        self.reset_children()
        return status


_INT_PREFIX = re.compile(r"[+-]?\d+")
_REAL_PREFIX = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def _to_int(text: str, enums: Mapping[str, int]) -> int | None:
    if text in enums:
        return enums[text]
    match = _INT_PREFIX.match(text)
    return int(match.group()) if match else None


def _to_real(text: str) -> float | None:
    match = _REAL_PREFIX.match(text)
    return float(match.group()) if match else None


def switch_matches(variable: str, case: str, enums: Mapping[str, int]) -> bool:
    """BT.CPP's ``CheckStringEquality``: equal strings, else equal integers, else equal reals."""
    if variable == case:
        return True
    left, right = _to_int(variable, enums), _to_int(case, enums)
    if left is not None and right is not None and left == right:
        return True
    real_left, real_right = _to_real(variable), _to_real(case)
    return real_left is not None and real_right is not None and real_left == real_right


class Switch(ControlNode):
    """BT.CPP ``SwitchN``: ``cases`` are the ``case_1`` ... ``case_N`` ports, the last child is the default."""

    def __init__(
        self,
        name: str,
        children: list[py_trees.behaviour.Behaviour],
        variable: PortValue | None,
        cases: list[PortValue | None],
        enums: Mapping[str, int] | None = None,
    ) -> None:
        super().__init__(name, children)
        self.variable = variable
        self.cases = cases
        self.enums = dict(enums or {})
        self.running_child = -1

    def bind_environment(self, env: BlackboardEnvironment) -> None:
        """The loader's environment: the registry's enums (``case_N`` may name one)."""
        self.enums = dict(env.enums)

    @staticmethod
    def _text(port: PortValue | None) -> str | None:
        if port is None or port.text is None:
            return None
        if port.key is None:
            return port.text
        try:
            return to_string(port.get())
        except BtMetaError:
            return None

    def execute(self) -> TickGenerator:
        match = len(self.cases)
        variable = self._text(self.variable)
        if variable is not None:
            for index, case in enumerate(self.cases):
                value = self._text(case)
                if value is not None and switch_matches(variable, value, self.enums):
                    match = index
                    break
        if self.running_child != -1 and self.running_child != match:
            self.reset_child(self.running_child)
        status = yield from self.tick_child(match)
        if status is SKIPPED:
            self.running_child = -1
            return SKIPPED
        if status == Status.RUNNING:
            self.running_child = match
        else:
            self.reset_children()
            self.running_child = -1
        return status

    def halt(self) -> None:
        self.running_child = -1
        super().halt()
