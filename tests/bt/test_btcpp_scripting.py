"""Differential tests of the script language, the script nodes and the pre/post-condition attributes against the
real BehaviorTree.CPP (behaviortreepy 0.1.4 = BT.CPP 4.8.2), over seeded random scripts and random trees.

Random scripts: each is run by a ``Script`` node after an initialising one; both engines must agree on whether it
loads, whether it raises at tick time, and on the printed value of every entry afterwards (BT.CPP's
``get_string``). Random trees: the tree generator of ``test_btcpp_conformance`` (copied in small here) with random
``_skipIf _successIf _failureIf _while _onSuccess _onFailure _onHalted _post`` attributes and Script /
ScriptCondition / Precondition nodes; per tick the root status (SKIPPED included), the ordered log of leaf ticks and
halts, and the counters the scripts write must be equal.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from xml.sax.saxutils import quoteattr

import behaviortreepy as btpy
import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.nodes.status import SKIPPED
from bt_meta.bt.nodes.ticking import tick_exactly_once, tick_once
from bt_meta.bt.registry import NodeType, default_registry
from bt_meta.bt.script import ScriptRuntimeError
from bt_meta.bt.script.values import to_string
from bt_meta.bt.xml.reader import load_tree_text
from bt_meta.errors import BtMetaError, TreeXMLError

pytestmark = pytest.mark.usefixtures("clean_blackboard")

KEYS = ("a", "b", "s", "x", "y", "z")
INIT = "a := 2; b := 1.5; s := 'ab'"


class _ScriptGenerator:
    def __init__(self, rng: random.Random) -> None:
        self.rng = rng

    def space(self) -> str:
        return self.rng.choice(["", " ", " ", "  "])

    def atom(self, depth: int) -> str:
        rng = self.rng
        pick = rng.random()
        if depth > 0 and pick < 0.15:
            return "(" + self.expr(depth - 1) + ")"
        return rng.choice(
            [
                "0", "1", "2", "3", "7", "0x1F", "+3", "1.5", "2.0", "0.0", "1e1", "2.5e-1",
                "'ab'", "'3'", '"c"', "''", "true", "false",
                "a", "b", "s", "@a", "x", "z",
            ]
        )  # fmt: skip

    def expr(self, depth: int) -> str:
        rng = self.rng
        if depth <= 0:
            return self.atom(0)
        pick = rng.random()
        sp = self.space
        if pick < 0.3:
            return self.atom(depth)
        if pick < 0.42:
            return rng.choice(["-", "!", "~"]) + sp() + self.atom(depth - 1)
        if pick < 0.5:
            return f"{self.expr(depth - 1)}{sp()}?{sp()}{self.expr(depth - 1)}{sp()}:{sp()}{self.atom(depth - 1)}"
        op = rng.choice(["+", "-", "*", "/", "..", "&", "|", "^", "&&", "||", "==", "!=", "<", ">", "<=", ">="])
        left = self.atom(depth - 1) if rng.random() < 0.5 else self.expr(depth - 1)
        return f"{left}{sp()}{op}{sp()}{self.atom(depth - 1)}"

    def statement(self) -> str:
        rng = self.rng
        count = rng.choice([1, 1, 2])
        parts = []
        for _ in range(count):
            target = rng.choice(["x", "y", "a", "b", "s", "z"])
            op = rng.choice([":=", ":=", ":=", "=", "+=", "-=", "*=", "/="])
            parts.append(f"{target}{self.space()}{op}{self.space()}{self.expr(rng.randint(0, 3))}")
        return ";".join(parts) if rng.random() < 0.5 else "; ".join(parts)


def _script_xml(code: str) -> str:
    return (
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence>'
        f"<Script code={quoteattr(INIT)}/><Script code={quoteattr(code)}/>"
        "</Sequence></BehaviorTree></root>"
    )


def _btcpp_outcome(xml: str) -> tuple[str, dict[str, str]]:
    factory = btpy.BehaviorTreeFactory()
    try:
        tree = factory.create_tree_from_text(xml)
    except Exception:
        return "load error", {}
    try:
        status = tree.tick_once().name
    except Exception:
        return "tick error", {}
    board = tree.root_blackboard()
    values = {}
    for key in KEYS:
        try:
            values[key] = board.get_string(key)
        except Exception:
            values[key] = "-"
    return status, values


def _our_outcome(xml: str) -> tuple[str, dict[str, str]]:
    py_trees.blackboard.Blackboard.clear()
    try:
        root = load_tree_text(xml)
    except TreeXMLError:
        return "load error", {}
    try:
        status = tick_once(root).name
    except ScriptRuntimeError:
        return "tick error", {}
    storage = py_trees.blackboard.Blackboard.storage
    return status, {key: to_string(storage[f"/{key}"]) if f"/{key}" in storage else "-" for key in KEYS}


def test_random_scripts_evaluate_like_behaviortree_cpp() -> None:
    outcomes: dict[str, int] = {}
    for seed in range(1500):
        code = _ScriptGenerator(random.Random(seed)).statement()
        xml = _script_xml(code)
        expected = _btcpp_outcome(xml)
        assert _our_outcome(xml) == expected, f"seed {seed}: {code!r}"
        outcomes[expected[0]] = outcomes.get(expected[0], 0) + 1
    # The sweep must exercise successes and both kinds of errors.
    assert outcomes.get("SUCCESS", 0) > 250
    assert outcomes.get("load error", 0) > 30 and outcomes.get("tick error", 0) > 50


@pytest.mark.parametrize(
    "code",
    [
        "x := -3", "x := +3", "x := 1 -3", "x := 3 / 2", "x := 0x1F", "x := 1e3", "x := 'a' .. 3.5",
        "x := 1 | 2 ^ 3 & 7", "x := !!0", "x := - -3", "x := 3 == 3 == 1", "x := 1 < 2 < 3", "x := 2.0000001 == 2",
        "x := (1 ? 2 : 3) ? 4 : 5", "x := 1 ? y := 2 : 3", "x := (y := 3) + 1", "x := 1/0", "x := -1/0",
        "x := 3; x = 4.0", "x := 3; x = '4'", "x := 2.5; x = 3", "x := 7; y := ~x", "x := 'a' + 'b'",
        "x := 1; x += 2", "x := 'a'; x += 'b'", "x := 3; x -= 0.5", "x := 1 || 0 && 0", "x := 0.5 || 0",
        "x := 9223372036854775807",
        # errors, at load and at tick
        "x := 1;", "x := 1 + 2 & 3", "x := y := 1", "truex := 1", "x := ~-1", "x := -!1", "x := 1..2", "x := 5 % 2",
        "x := 9223372036854775808", "x = 3", "x := '3' + 1", "x := 1 || 2", "x := 1 .. 2", "x := 'a' < 3",
        "x := 1.5 & 1", "x := 3; x = 2.5", "x := 'a'; x = 1", "x := -'a'", "x := 'a' ? 1 : 2", "   ",
        # one operator group per expression, across comparisons and && / ||
        "x := 1 & 2 <= 3 - 1", "x := 1 + 2 == 3 .. 'a'", "x := 1 & 2 == 3 & 1", "x := !1 == 1 + 0",
        "x := 1 + 1 == 2 && 1 & 1", "x := 1 < 2 == !0", "x := 1 ? 1 + 1 : 2 & 2", "x := (1 + 1) == (2 & 2)",
    ],
)  # fmt: skip
def test_script_corner_cases_match_behaviortree_cpp(code: str) -> None:
    xml = _script_xml(code)
    assert _our_outcome(xml) == _btcpp_outcome(xml)


def test_enums_registered_by_name_are_numbers_in_scripts() -> None:
    registry = default_registry()
    registry.register_enum("RED", 1)
    registry.register_enum("BLUE", 2)
    root = load_tree_text(_script_xml("x := BLUE; y := x == 2; z := RED + BLUE"), registry)
    assert tick_once(root) == Status.SUCCESS
    storage = py_trees.blackboard.Blackboard.storage
    assert (storage["/x"], storage["/y"], storage["/z"]) == (2.0, 1.0, 3.0)


# --- random trees with pre/post conditions -------------------------------------------------------------------

STATUSES = ("SUCCESS", "FAILURE", "RUNNING")
PRE = {
    "_skipIf": ["@a > 2", "@b == 1", "@a == @b", "false"],
    "_successIf": ["@b == 2", "@a > 3"],
    "_failureIf": ["@a == 1", "@b > 3"],
    "_while": ["@b < 3", "@a != 2", "true"],
}
POST = {
    "_onSuccess": ["@a += 1", "@b := @b + 1"],
    "_onFailure": ["@b += 1", "@a := @a > 3 ? 0 : @a + 2"],
    "_onHalted": ["@b := 0", "@a += 1"],
    "_post": ["@a := @a > 4 ? 0 : @a", "@b := @b > 4 ? 1 : @b"],
}


class _TreeGenerator:
    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.leaves: dict[str, list[str]] = {}
        self.subtrees: dict[str, str] = {}
        self.kinds: set[str] = set()

    def conditions(self) -> str:
        rng = self.rng
        attrs = []
        for table in (PRE, POST):
            for attr, scripts in table.items():
                if rng.random() < 0.12:
                    attrs.append(f" {attr}={quoteattr(rng.choice(scripts))}")
                    self.kinds.add(attr)
        return "".join(attrs)

    def leaf(self) -> str:
        rng = self.rng
        pick = rng.random()
        if pick < 0.1:
            self.kinds.add("Script")
            return f"<Script code={quoteattr(rng.choice(['@a += 1', '@b := @a', '@a := 0']))}{self.conditions()}/>"
        if pick < 0.2:
            self.kinds.add("ScriptCondition")
            code = quoteattr(rng.choice(["@a < 3", "@b >= 1", "@a == @b"]))
            return f"<ScriptCondition code={code}{self.conditions()}/>"
        if pick < 0.26:
            kind = rng.choice(["UnsetBlackboard", "WasEntryUpdated", "Sleep", "SetBlackboard"])
            self.kinds.add(kind)
            if kind == "UnsetBlackboard":
                return f'<UnsetBlackboard key="{rng.choice(["w", "q"])}"{self.conditions()}/>'
            if kind == "WasEntryUpdated":
                return f'<WasEntryUpdated entry="{rng.choice(["{@w}", "@w", "{@q}"])}"{self.conditions()}/>'
            if kind == "Sleep":
                return f'<Sleep msec="0"{self.conditions()}/>'
            return f'<SetBlackboard output_key="@w" value="{rng.choice(["1", "2"])}"{self.conditions()}/>'
        name = f"L{len(self.leaves)}"
        self.leaves[name] = [rng.choice(STATUSES) for _ in range(rng.randint(1, 4))]
        return f"<{name}{self.conditions()}/>"

    def node(self, depth: int) -> str:
        rng = self.rng
        if depth <= 0 or rng.random() < 0.25:
            return self.leaf()
        kind = rng.choice(
            ["Sequence", "SequenceWithMemory", "ReactiveSequence", "Fallback", "ReactiveFallback", "Parallel",
             "Inverter", "ForceSuccess", "ForceFailure", "Repeat", "RetryUntilSuccessful", "KeepRunningUntilFailure",
             "Precondition", "SubTree", "IfThenElse", "WhileDoElse", "Switch2", "Switch3", "ParallelAll", "RunOnce",
             "AsyncSequence", "AsyncFallback", "LoopInt", "LoopString", "SkipUnlessUpdated",
             "WaitValueUpdate"]
        )  # fmt: skip
        self.kinds.add(kind)
        cond = self.conditions()
        if kind == "SubTree":
            sub_id = f"Sub{len(self.subtrees)}"
            self.subtrees[sub_id] = ""
            self.subtrees[sub_id] = self.node(depth - 1)
            return f'<SubTree ID="{sub_id}"{cond}/>'
        if kind in {"Inverter", "ForceSuccess", "ForceFailure", "KeepRunningUntilFailure"}:
            return f"<{kind}{cond}>{self.node(depth - 1)}</{kind}>"
        if kind == "Repeat":
            return f'<Repeat num_cycles="{rng.choice([1, 2, 3])}"{cond}>{self.node(depth - 1)}</Repeat>'
        if kind == "RetryUntilSuccessful":
            attempts = rng.choice([1, 2, 3])
            child = self.node(depth - 1)
            return f'<RetryUntilSuccessful num_attempts="{attempts}"{cond}>{child}</RetryUntilSuccessful>'
        if kind in ("IfThenElse", "WhileDoElse"):
            children = "".join(self.node(depth - 1) for _ in range(rng.choice([2, 3])))
            return f"<{kind}{cond}>{children}</{kind}>"
        if kind.startswith("Switch"):
            cases = int(kind[-1])
            values = "".join(f' case_{i}="{rng.choice(["0", "1", "2", "1.0", "x"])}"' for i in range(1, cases + 1))
            children = "".join(self.node(depth - 1) for _ in range(cases + 1))
            return f'<{kind} variable="{rng.choice(["{@a}", "{@b}", "1"])}"{values}{cond}>{children}</{kind}>'
        if kind == "RunOnce":
            skip = rng.choice(["", ' then_skip="false"', ' then_skip="true"'])
            return f"<RunOnce{skip}{cond}>{self.node(depth - 1)}</RunOnce>"
        if kind in ("LoopInt", "LoopString"):
            queue = rng.choice(["1;2;3", "4", "0;0"])
            empty = rng.choice(["", ' if_empty="FAILURE"', ' if_empty="SKIPPED"'])
            out = "{@li}" if kind == "LoopInt" else "{@ls}"
            return f'<{kind} queue="{queue}" value="{out}"{empty}{cond}>{self.node(depth - 1)}</{kind}>'
        if kind in ("SkipUnlessUpdated", "WaitValueUpdate"):
            entry = rng.choice(["{@a}", "@w", "{@q}"])
            return f'<{kind} entry="{entry}"{cond}>{self.node(depth - 1)}</{kind}>'
        if kind == "Precondition":
            test = quoteattr(rng.choice(["@a < 3", "@b != 2", "@a == 0"]))
            otherwise = rng.choice(["FAILURE", "SUCCESS", "SKIPPED", "RUNNING"])
            return f'<Precondition if={test} else="{otherwise}"{cond}>{self.node(depth - 1)}</Precondition>'
        children = [self.node(depth - 1) for _ in range(rng.randint(1, 4))]
        attrs = ""
        if kind == "Parallel":
            n = len(children)
            success = rng.choice([c for c in range(-n, n + 1) if c != 0])
            failure = rng.choice([c for c in range(-n, n + 1) if c != 0])
            attrs = f' success_count="{success}" failure_count="{failure}"'
        if kind == "ParallelAll":
            n = len(children)
            attrs = f' max_failures="{rng.choice([c for c in range(-n, n + 1) if c != 0])}"'
        return f"<{kind}{attrs}{cond}>{''.join(children)}</{kind}>"


def generate_tree(seed: int) -> tuple[str, dict[str, list[str]], set[str]]:
    gen = _TreeGenerator(random.Random(seed))
    main = f'<Sequence><Script code="a := 0; b := 0"/>{gen.node(4)}</Sequence>'
    trees = [f'<BehaviorTree ID="Main">{main}</BehaviorTree>']
    trees += [f'<BehaviorTree ID="{sub}">{body}</BehaviorTree>' for sub, body in gen.subtrees.items()]
    return f'<root BTCPP_format="4" main_tree_to_execute="Main">{"".join(trees)}</root>', gen.leaves, gen.kinds


Step = Callable[[], tuple[str, list[tuple[str, str]], tuple[str, str]]]


def _btcpp_steps(xml: str, leaves: dict[str, list[str]], mode: str) -> Step:
    log: list[tuple[str, str]] = []
    factory = btpy.BehaviorTreeFactory()
    for name, script in leaves.items():
        calls = [0]

        def step(_node: object, name: str = name, script: list[str] = script, calls: list[int] = calls) -> object:
            status = script[calls[0] % len(script)]
            calls[0] += 1
            log.append((name, status))
            return getattr(btpy.NodeStatus, status)

        def halted(_node: object, name: str = name) -> None:
            log.append((name, "HALT"))

        factory.register_simple_stateful_action(name, step, step, halted)
    tree = factory.create_tree_from_text(xml)

    def tick() -> tuple[str, list[tuple[str, str]], tuple[str, str]]:
        try:
            status = (tree.tick_exactly_once() if mode == "exactly_once" else tree.tick_once()).name
        except Exception:
            status = "error"
        events = list(log)
        log.clear()
        board = tree.root_blackboard()
        keys = set(board.get_keys())
        return status, events, tuple(board.get_string(k) if k in keys else "-" for k in ("a", "b"))  # type: ignore[return-value]

    tick.tree = tree  # type: ignore[attr-defined]
    return tick


class _Leaf(py_trees.behaviour.Behaviour):
    """Our side of behaviortreepy's ``register_simple_stateful_action`` leaf."""

    def __init__(self, name: str, script: list[str], log: list[tuple[str, str]]) -> None:
        super().__init__(name)
        self.script = script
        self.calls = 0
        self.log = log

    def update(self) -> Status:
        if self.status in (Status.SUCCESS, Status.FAILURE):
            # BT.CPP's StatefulActionNode ticked again before it was reset returns its status without a callback
            # (WhileDoElse does that to its condition).
            return self.status
        status = self.script[self.calls % len(self.script)]
        self.calls += 1
        self.log.append((self.name, status))
        return Status[status]

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING:
            self.log.append((self.name, "HALT"))


def _our_steps(xml: str, leaves: dict[str, list[str]], mode: str) -> Step:
    log: list[tuple[str, str]] = []
    registry = default_registry()
    for name, script in leaves.items():

        def factory(*, name: str, ports: dict, children: list, script: list[str] = script) -> _Leaf:
            return _Leaf(name, script, log)

        registry.register(NodeType(name, "Action", [], factory))
    py_trees.blackboard.Blackboard.clear()
    root = load_tree_text(xml, registry)

    def tick() -> tuple[str, list[tuple[str, str]], tuple[str, str]]:
        try:
            status = (tick_exactly_once(root) if mode == "exactly_once" else tick_once(root)).name
        except BtMetaError:  # BT.CPP throws on the same trees (script errors, a skipped IfThenElse condition)
            status = "error"
        events = list(log)
        log.clear()
        storage = py_trees.blackboard.Blackboard.storage
        return status, events, tuple(to_string(storage[k]) if k in storage else "-" for k in ("/a", "/b"))  # type: ignore[return-value]

    return tick


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_random_trees_with_conditions_tick_like_behaviortree_cpp(mode: str) -> None:
    kinds: set[str] = set()
    skipped_roots = 0
    for seed in range(250):
        xml, leaves, used = generate_tree(seed)
        kinds |= used
        theirs = _btcpp_steps(xml, leaves, mode)
        ours = _our_steps(xml, leaves, mode)
        for tick in range(12):
            want = theirs()
            got = ours()
            assert got == want, f"seed {seed} mode {mode} tick {tick}\nXML: {xml}\nBT.CPP: {want}\nours: {got}"
            skipped_roots += want[0] == "SKIPPED"
            if want[0] == "error":
                break
    assert kinds >= {*PRE, *POST, "Script", "ScriptCondition", "Precondition", "SubTree", "Parallel", *NEW_BUILTINS}


# Every BT.CPP 4.8.2 built-in that the older conformance test does not generate (bt_factory.cpp's registry).
NEW_BUILTINS = {
    "IfThenElse", "WhileDoElse", "Switch2", "Switch3", "ParallelAll", "RunOnce", "AsyncSequence", "AsyncFallback",
    "LoopInt", "LoopString", "SkipUnlessUpdated", "WaitValueUpdate", "UnsetBlackboard",
    "WasEntryUpdated", "Sleep",
}  # fmt: skip
BTCPP_4_8_BUILTINS = {
    "Fallback", "AsyncFallback", "Sequence", "AsyncSequence", "SequenceWithMemory", "Parallel",
    "ParallelAll", "ReactiveSequence", "ReactiveFallback", "IfThenElse", "WhileDoElse", "Inverter",
    "RetryUntilSuccessful", "KeepRunningUntilFailure", "Repeat", "Timeout", "Delay", "RunOnce", "ForceSuccess",
    "ForceFailure", "AlwaysSuccess", "AlwaysFailure", "Script", "ScriptCondition", "SetBlackboard", "Sleep",
    "UnsetBlackboard", "SubTree", "Precondition", "Switch2", "Switch3", "Switch4", "Switch5", "Switch6", "LoopInt",
    "LoopBool", "LoopDouble", "LoopString", "WasEntryUpdated", "SkipUnlessUpdated", "WaitValueUpdate",
}  # fmt: skip


def test_every_behaviortree_cpp_builtin_is_registered() -> None:
    assert set(default_registry().ids()) == BTCPP_4_8_BUILTINS


def test_a_skipped_root_returns_skipped() -> None:
    body = '<Sequence><AlwaysSuccess _skipIf="true"/></Sequence>'
    xml = f'<root BTCPP_format="4"><BehaviorTree ID="M">{body}</BehaviorTree></root>'
    assert tick_once(load_tree_text(xml)) is SKIPPED


@pytest.mark.parametrize(
    "body",
    ['<Delay delay_msec="40"><L0/></Delay>', '<Sequence><Sleep msec="40"/><L0/></Sequence>'],
)
def test_delay_and_sleep_wait_like_behaviortree_cpp(body: str) -> None:
    """Wall-clock waits: BT.CPP's timer thread against our clock check at the next tick."""
    import time

    xml = f'<root BTCPP_format="4"><BehaviorTree ID="M">{body}</BehaviorTree></root>'
    leaves = {"L0": ["SUCCESS"]}

    def trace(step: Step) -> list[tuple[str, list[tuple[str, str]]]]:
        result = []
        for pause in (0.0, 0.2, 0.0):
            time.sleep(pause)
            status, events, _ = step()
            result.append((status, events))
        return result

    expected = [("RUNNING", []), ("SUCCESS", [("L0", "SUCCESS")]), ("RUNNING", [])]
    assert trace(_btcpp_steps(xml, leaves, "exactly_once")) == expected
    assert trace(_our_steps(xml, leaves, "exactly_once")) == expected


def test_autoremap_keeps_underscore_keys_private_like_behaviortree_cpp() -> None:
    xml = (
        '<root BTCPP_format="4" main_tree_to_execute="M"><BehaviorTree ID="M"><Sequence>'
        "<Script code=\"x := 1; _y := 1\"/><SubTree ID=\"S\" _autoremap=\"true\"/></Sequence></BehaviorTree>"
        '<BehaviorTree ID="S"><Script code="x := 5; _y := 5"/></BehaviorTree></root>'
    )
    theirs = btpy.BehaviorTreeFactory().create_tree_from_text(xml)
    assert theirs.tick_once().name == "SUCCESS"
    assert tick_once(load_tree_text(xml)) == Status.SUCCESS
    storage = py_trees.blackboard.Blackboard.storage
    board = theirs.root_blackboard()
    assert (to_string(storage["/x"]), to_string(storage["/_y"])) == (board.get_string("x"), board.get_string("_y"))
    assert (board.get_string("x"), board.get_string("_y")) == ("5", "1")


def test_written_xml_keeps_scripts_conditions_and_new_builtins() -> None:
    """Our writer's output of a loaded random tree runs identically in BT.CPP (conditions, scripts, every built-in)."""
    from bt_meta.bt.xml.writer import tree_to_xml

    for seed in range(60):
        xml, leaves, _ = generate_tree(seed)
        registry = default_registry()
        for name in leaves:
            registry.register(NodeType(name, "Action", [], lambda **_: py_trees.behaviours.Success()))
        written = tree_to_xml(load_tree_text(xml, registry), registry=registry)
        original = _btcpp_steps(xml, leaves, "exactly_once")
        rewritten = _btcpp_steps(written, leaves, "exactly_once")
        assert [rewritten() for _ in range(10)] == [original() for _ in range(10)], f"seed {seed}\n{written}"


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_larger_sweep_of_trees_with_conditions(mode: str) -> None:
    for seed in range(1000, 2500):
        xml, leaves, _ = generate_tree(seed)
        theirs = _btcpp_steps(xml, leaves, mode)
        ours = _our_steps(xml, leaves, mode)
        for tick in range(20):
            want, got = theirs(), ours()
            assert got == want, f"seed {seed} mode {mode} tick {tick}\nXML: {xml}\nBT.CPP: {want}\nours: {got}"
            if want[0] == "error":
                break


@pytest.mark.slow
def test_larger_sweep_of_random_scripts() -> None:
    for seed in range(10_000, 16_000):
        code = _ScriptGenerator(random.Random(seed)).statement()
        xml = _script_xml(code)
        assert _our_outcome(xml) == _btcpp_outcome(xml), f"seed {seed}: {code!r}"
