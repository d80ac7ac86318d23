"""py_trees behaviours with BehaviorTree.CPP v4 tick semantics, and their registry entries.

Modules (one concept each):

* :mod:`~bt_meta.bt.nodes.base` -- BT.CPP tick/halt/reset discipline for py_trees composites and decorators
* :mod:`~bt_meta.bt.nodes.sequences` -- Sequence, SequenceWithMemory, ReactiveSequence, AsyncSequence
* :mod:`~bt_meta.bt.nodes.fallbacks` -- Fallback, ReactiveFallback, AsyncFallback
* :mod:`~bt_meta.bt.nodes.parallel` -- Parallel with success/failure counts, ParallelAll
* :mod:`~bt_meta.bt.nodes.branches` -- IfThenElse, WhileDoElse, Switch2 ... Switch6
* :mod:`~bt_meta.bt.nodes.modifiers` -- Inverter, ForceSuccess, ForceFailure, KeepRunningUntilFailure, RunOnce
* :mod:`~bt_meta.bt.nodes.loops` -- Repeat, RetryUntilSuccessful, LoopInt/LoopDouble/LoopBool/LoopString
* :mod:`~bt_meta.bt.nodes.timeout` -- Timeout (injectable clock)
* :mod:`~bt_meta.bt.nodes.timers` -- Delay, Sleep (injectable clock)
* :mod:`~bt_meta.bt.nodes.leaves` -- AlwaysSuccess, AlwaysFailure, SetBlackboard, UnsetBlackboard
* :mod:`~bt_meta.bt.nodes.updates` -- WasEntryUpdated, SkipUnlessUpdated, WaitValueUpdate
* :mod:`~bt_meta.bt.nodes.stubs` -- stand-ins for nodes nobody implements (``--stub-unknown``)
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
from py_trees.common import Status

from bt_meta.bt.nodes.base import PortValue
from bt_meta.bt.nodes.branches import IfThenElse, Switch, WhileDoElse
from bt_meta.bt.nodes.fallbacks import AsyncFallback, Fallback, ReactiveFallback
from bt_meta.bt.nodes.leaves import AlwaysFailure, AlwaysSuccess, SetBlackboard, UnsetBlackboard
from bt_meta.bt.nodes.loops import LoopQueue, Repeat, RetryUntilSuccessful
from bt_meta.bt.nodes.modifiers import ForceFailure, ForceSuccess, Inverter, KeepRunningUntilFailure, RunOnce
from bt_meta.bt.nodes.parallel import FAILURE_COUNT, SUCCESS_COUNT, Parallel, ParallelAll
from bt_meta.bt.nodes.scripting import Precondition, Script, ScriptCondition
from bt_meta.bt.nodes.sequences import AsyncSequence, ReactiveSequence, Sequence, SequenceWithMemory
from bt_meta.bt.nodes.status import SKIPPED, parse_status
from bt_meta.bt.nodes.subtree import SubTree
from bt_meta.bt.nodes.timeout import Timeout
from bt_meta.bt.nodes.timers import Delay, Sleep
from bt_meta.bt.nodes.updates import EntryUpdatedDecorator, WasEntryUpdated
from bt_meta.bt.registry import NodeType, PortSpec, blackboard_key

__all__ = [
    "UNSUPPORTED_BUILTINS",
    "AlwaysFailure",
    "AlwaysSuccess",
    "AsyncFallback",
    "AsyncSequence",
    "Delay",
    "EntryUpdatedDecorator",
    "Fallback",
    "ForceFailure",
    "ForceSuccess",
    "IfThenElse",
    "Inverter",
    "KeepRunningUntilFailure",
    "LoopQueue",
    "Parallel",
    "ParallelAll",
    "Precondition",
    "ReactiveFallback",
    "ReactiveSequence",
    "Repeat",
    "RetryUntilSuccessful",
    "RunOnce",
    "Script",
    "ScriptCondition",
    "Sequence",
    "SequenceWithMemory",
    "SetBlackboard",
    "Sleep",
    "SubTree",
    "Switch",
    "Timeout",
    "UnsetBlackboard",
    "WasEntryUpdated",
    "WhileDoElse",
    "builtin_node_types",
]

Behaviour = py_trees.behaviour.Behaviour

# BehaviorTree.CPP 4.8 built-ins that bt-meta does not implement (none left; kept for the reader's message).
UNSUPPORTED_BUILTINS: frozenset[str] = frozenset()

NUM_CYCLES = PortSpec("num_cycles", "input", "int", None, "repeat a successful child this many times (-1: forever)")
NUM_ATTEMPTS = PortSpec("num_attempts", "input", "int", None, "retry a failing child this many times (-1: forever)")
MSEC = PortSpec("msec", "input", "unsigned int", None, "halt the child after this many milliseconds")
SUBTREE_ID = PortSpec("ID", "input", "std::string", None, "the <BehaviorTree ID> this SubTree runs")
VALUE = PortSpec("value", "input", "std::string", None, "value to write")
DELAY_MSEC = PortSpec("delay_msec", "input", "unsigned int", None, "tick the child after this many milliseconds")
SLEEP_MSEC = PortSpec("msec", "input", "unsigned int", None, "milliseconds to wait")
MAX_FAILURES = PortSpec("max_failures", "input", "int", "1", "children that must fail for FAILURE (negative: n+1+v)")
THEN_SKIP = PortSpec("then_skip", "input", "bool", "true", "after the first run: SKIPPED (true) or the same status")
UNSET_KEY = PortSpec("key", "input", "std::string", None, "entry to remove")
ENTRY = PortSpec("entry", "input", "BT::Any", None, "entry to watch")
VARIABLE = PortSpec("variable", "input", "std::string", None, "value compared with every case")
IF_EMPTY = PortSpec("if_empty", "input", "BT::NodeStatus", "SUCCESS", "status when the queue is empty")
LOOP_VALUE = {
    item: PortSpec("value", "output", type_name, None, "the item popped from the queue")
    for item, type_name in (("int", "int"), ("double", "double"), ("bool", "bool"), ("string", "std::string"))
}
LOOP_QUEUE = {
    item: PortSpec("queue", "inout", f"std::shared_ptr<std::deque<{type_name}>>", None, "items, e.g. 1;2;3")
    for item, type_name in (("int", "int"), ("double", "double"), ("bool", "bool"), ("string", "std::string"))
}
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


def _children_factory(cls: type[Behaviour]) -> Any:
    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        return cls(name, children)

    return factory


def _switch(cases: int) -> Any:
    case_specs = [PortSpec(f"case_{i}", "input", "std::string", None, f"value selecting child {i}") for i in
                  range(1, cases + 1)]

    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        variable = PortValue(VARIABLE, ports["variable"]) if "variable" in ports else None
        values = [PortValue(spec, ports[spec.name]) if spec.name in ports else None for spec in case_specs]
        return Switch(name, children, variable, values)

    return factory, [VARIABLE, *case_specs]


def _parallel_all(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return ParallelAll(name, children, PortValue(MAX_FAILURES, ports["max_failures"]))


def _run_once(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return RunOnce(name, children[0], PortValue(THEN_SKIP, ports["then_skip"]))


def _delay(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return Delay(name, children[0], PortValue(DELAY_MSEC, ports["delay_msec"]))


def _sleep(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return Sleep(name, PortValue(SLEEP_MSEC, ports["msec"]))


def _entry_key(text: str) -> str:
    return blackboard_key(text) or text.strip()


def _unset(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return UnsetBlackboard(name, ports["key"])


def _was_updated(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
    return WasEntryUpdated(name, _entry_key(ports["entry"]))


def _updated_decorator(if_not_updated: Any) -> Any:
    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        return EntryUpdatedDecorator(name, children[0], _entry_key(ports["entry"]), if_not_updated)

    return factory


def _loop(item: str) -> Any:
    def factory(*, name: str, ports: dict[str, str], children: list[Behaviour]) -> Behaviour:
        otherwise = ports["if_empty"]
        if_empty: Any = PortValue(IF_EMPTY, otherwise) if blackboard_key(otherwise) is not None else parse_status(
            otherwise)
        return LoopQueue(name, children[0], PortValue(LOOP_QUEUE[item], ports["queue"]),
                         PortValue(LOOP_VALUE[item], ports.get("value")), if_empty, item)

    return factory


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
        node("AsyncSequence", "Control", _control(AsyncSequence)),
        node("AsyncFallback", "Control", _control(AsyncFallback)),
        node("IfThenElse", "Control", _children_factory(IfThenElse), children=(2, 3)),
        node("WhileDoElse", "Control", _children_factory(WhileDoElse), children=(2, 3)),
        *[node(f"Switch{n}", "Control", _switch(n)[0], _switch(n)[1], children=(n + 1, n + 1)) for n in range(2, 7)],
        node("ParallelAll", "Control", _parallel_all, [MAX_FAILURES]),
        node("RunOnce", "Decorator", _run_once, [THEN_SKIP]),
        node("Delay", "Decorator", _delay, [DELAY_MSEC]),
        node("Sleep", "Action", _sleep, [SLEEP_MSEC]),
        node("UnsetBlackboard", "Action", _unset, [UNSET_KEY]),
        node("WasEntryUpdated", "Action", _was_updated, [ENTRY]),
        node("SkipUnlessUpdated", "Decorator", _updated_decorator(SKIPPED), [ENTRY]),
        node("WaitValueUpdate", "Decorator", _updated_decorator(Status.RUNNING), [ENTRY]),
        node("LoopInt", "Decorator", _loop("int"), [LOOP_QUEUE["int"], IF_EMPTY, LOOP_VALUE["int"]]),
        node("LoopDouble", "Decorator", _loop("double"), [LOOP_QUEUE["double"], IF_EMPTY, LOOP_VALUE["double"]]),
        node("LoopBool", "Decorator", _loop("bool"), [LOOP_QUEUE["bool"], IF_EMPTY, LOOP_VALUE["bool"]]),
        node("LoopString", "Decorator", _loop("string"), [LOOP_QUEUE["string"], IF_EMPTY, LOOP_VALUE["string"]]),
        node("Script", "Action", _script, [CODE]),
        node("ScriptCondition", "Condition", _script_condition, [CONDITION_CODE]),
        node("Precondition", "Decorator", _precondition, [IF, ELSE]),
        node("SubTree", "SubTree", _subtree, [SUBTREE_ID], children=(1, 1)),
    ]
