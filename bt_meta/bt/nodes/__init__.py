"""py_trees behaviours with BehaviorTree.CPP v4 tick semantics, and their registry entries.

Modules (one concept each):

* :mod:`~bt_meta.bt.nodes.base` -- BT.CPP tick/halt/reset discipline for py_trees composites and decorators
* :mod:`~bt_meta.bt.nodes.sequences` -- Sequence, SequenceWithMemory, ReactiveSequence
* :mod:`~bt_meta.bt.nodes.fallbacks` -- Fallback, ReactiveFallback
* :mod:`~bt_meta.bt.nodes.parallel` -- Parallel with success/failure counts
* :mod:`~bt_meta.bt.nodes.modifiers` -- Inverter, ForceSuccess, ForceFailure, KeepRunningUntilFailure
* :mod:`~bt_meta.bt.nodes.loops` -- Repeat, RetryUntilSuccessful
* :mod:`~bt_meta.bt.nodes.timeout` -- Timeout (injectable clock)
* :mod:`~bt_meta.bt.nodes.leaves` -- AlwaysSuccess, AlwaysFailure, SetBlackboard
* :mod:`~bt_meta.bt.nodes.scripting` -- Script, ScriptCondition, Precondition (BT.CPP's script language)
* :mod:`~bt_meta.bt.nodes.conditions` -- the ``_skipIf`` ... ``_post`` pre/post-condition attributes
* :mod:`~bt_meta.bt.nodes.status` -- BT.CPP's SKIPPED status
* :mod:`~bt_meta.bt.nodes.entries` -- blackboard writes with BT.CPP's update counts, the script environment
* :mod:`~bt_meta.bt.nodes.subtree` -- SubTree
* :mod:`~bt_meta.bt.nodes.ticking` -- tick_once / tick_exactly_once and the wake-up signal of a tree

:func:`builtin_node_types` returns the :class:`~bt_meta.bt.registry.NodeType` of every built-in above;
:data:`UNSUPPORTED_BUILTINS` names BehaviorTree.CPP built-ins bt-meta does not implement (the reader says so).
"""

from __future__ import annotations

from typing import Any

import py_trees

from bt_meta.bt.nodes.base import PortValue
from bt_meta.bt.nodes.fallbacks import Fallback, ReactiveFallback
from bt_meta.bt.nodes.leaves import AlwaysFailure, AlwaysSuccess, SetBlackboard
from bt_meta.bt.nodes.loops import Repeat, RetryUntilSuccessful
from bt_meta.bt.nodes.modifiers import ForceFailure, ForceSuccess, Inverter, KeepRunningUntilFailure
from bt_meta.bt.nodes.parallel import FAILURE_COUNT, SUCCESS_COUNT, Parallel
from bt_meta.bt.nodes.scripting import Precondition, Script, ScriptCondition, parse_status
from bt_meta.bt.nodes.sequences import ReactiveSequence, Sequence, SequenceWithMemory
from bt_meta.bt.nodes.subtree import SubTree
from bt_meta.bt.nodes.timeout import Timeout
from bt_meta.bt.registry import NodeType, PortSpec, blackboard_key

__all__ = [
    "UNSUPPORTED_BUILTINS",
    "AlwaysFailure",
    "AlwaysSuccess",
    "Fallback",
    "ForceFailure",
    "ForceSuccess",
    "Inverter",
    "KeepRunningUntilFailure",
    "Parallel",
    "Precondition",
    "ReactiveFallback",
    "ReactiveSequence",
    "Repeat",
    "RetryUntilSuccessful",
    "Script",
    "ScriptCondition",
    "Sequence",
    "SequenceWithMemory",
    "SetBlackboard",
    "SubTree",
    "Timeout",
    "builtin_node_types",
]

Behaviour = py_trees.behaviour.Behaviour

# BehaviorTree.CPP v4 built-ins that bt-meta does not implement (mostly need its scripting language or threads).
UNSUPPORTED_BUILTINS: frozenset[str] = frozenset(
    {
        "AsyncSequence",
        "AsyncFallback",
        "Delay",
        "EntryUpdatedAction",
        "EntryUpdatedDecorator",
        "IfThenElse",
        "LoopBool",
        "LoopDouble",
        "LoopInt",
        "LoopString",
        "ParallelAll",
        "RunOnce",
        "SkipUnlessUpdated",
        "Sleep",
        "Switch2",
        "Switch3",
        "Switch4",
        "Switch5",
        "Switch6",
        "UnsetBlackboard",
        "WaitValueUpdate",
        "WasEntryUpdated",
        "WhileDoElse",
    }
)

NUM_CYCLES = PortSpec("num_cycles", "input", "int", None, "repeat a successful child this many times (-1: forever)")
NUM_ATTEMPTS = PortSpec("num_attempts", "input", "int", None, "retry a failing child this many times (-1: forever)")
MSEC = PortSpec("msec", "input", "unsigned int", None, "halt the child after this many milliseconds")
SUBTREE_ID = PortSpec("ID", "input", "std::string", None, "the <BehaviorTree ID> this SubTree runs")
VALUE = PortSpec("value", "input", "std::string", None, "value to write")
CODE = PortSpec("code", "input", "std::string", None, "script to run")
CONDITION_CODE = PortSpec("code", "input", "std::string", None, "script that gives true or false")
IF = PortSpec("if", "input", "std::string", None, "script: tick the child when it gives true")
ELSE = PortSpec("else", "input", "BT::NodeStatus", "FAILURE", "status returned when 'if' gives false")
OUTPUT_KEY = PortSpec("output_key", "inout", "std::string", None, "blackboard entry to write")


def _control(cls: type[Behaviour]) -> Any:
    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        return cls(name=name, children=children)

    return factory


def _decorator(cls: type[Behaviour]) -> Any:
    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        return cls(name=name, child=children[0])

    return factory


def _leaf(cls: type[Behaviour]) -> Any:
    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        return cls(name=name)

    return factory


def _parallel(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return Parallel(
        name=name,
        children=children,
        success_count=PortValue(SUCCESS_COUNT, ports["success_count"]),
        failure_count=PortValue(FAILURE_COUNT, ports["failure_count"]),
    )


def _repeat(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return Repeat(name=name, child=children[0], num_cycles=PortValue(NUM_CYCLES, ports["num_cycles"]))


def _retry(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return RetryUntilSuccessful(
        name=name, child=children[0], num_attempts=PortValue(NUM_ATTEMPTS, ports["num_attempts"])
    )


def _timeout(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return Timeout(name=name, child=children[0], msec=PortValue(MSEC, ports["msec"]))


def _set_blackboard(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return SetBlackboard(name=name, value=PortValue(VALUE, ports["value"]), output_key=ports["output_key"])


def _script(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return Script(name, PortValue(CODE, ports["code"]))


def _script_condition(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return ScriptCondition(name, PortValue(CONDITION_CODE, ports["code"]))


def _precondition(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    otherwise = ports["else"]
    value: Any = PortValue(ELSE, otherwise) if blackboard_key(otherwise) is not None else parse_status(otherwise)
    return Precondition(name, children[0], PortValue(IF, ports["if"]), value)


def _subtree(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return SubTree(name=name, child=children[0], tree_id=ports["ID"])


def builtin_node_types() -> list[NodeType]:
    """Every BehaviorTree.CPP built-in bt-meta implements, with BT.CPP's port declarations."""

    def node(node_id: str, category: Any, factory: Any, ports: list[PortSpec] | None = None, **kw: Any) -> NodeType:
        return NodeType(node_id, category, ports or [], factory, builtin=True, **kw)

    return [
        node("Sequence", "Control", _control(Sequence)),
        node("SequenceWithMemory", "Control", _control(SequenceWithMemory)),
        node("ReactiveSequence", "Control", _control(ReactiveSequence)),
        node("Fallback", "Control", _control(Fallback)),
        node("ReactiveFallback", "Control", _control(ReactiveFallback)),
        node("Parallel", "Control", _parallel, [SUCCESS_COUNT, FAILURE_COUNT]),
        node("Inverter", "Decorator", _decorator(Inverter)),
        node("ForceSuccess", "Decorator", _decorator(ForceSuccess)),
        node("ForceFailure", "Decorator", _decorator(ForceFailure)),
        node("KeepRunningUntilFailure", "Decorator", _decorator(KeepRunningUntilFailure)),
        node("Repeat", "Decorator", _repeat, [NUM_CYCLES]),
        node("RetryUntilSuccessful", "Decorator", _retry, [NUM_ATTEMPTS]),
        node("Timeout", "Decorator", _timeout, [MSEC]),
        node("AlwaysSuccess", "Action", _leaf(AlwaysSuccess)),
        node("AlwaysFailure", "Action", _leaf(AlwaysFailure)),
        node("SetBlackboard", "Action", _set_blackboard, [VALUE, OUTPUT_KEY]),
        node("Script", "Action", _script, [CODE]),
        node("ScriptCondition", "Condition", _script_condition, [CONDITION_CODE]),
        node("Precondition", "Decorator", _precondition, [IF, ELSE]),
        node("SubTree", "SubTree", _subtree, [SUBTREE_ID], children=(1, 1)),
    ]
