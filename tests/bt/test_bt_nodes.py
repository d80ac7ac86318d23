"""BT.CPP built-in nodes on py_trees and the node registry (the differential test lives in test_btcpp_conformance)."""

from __future__ import annotations

import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt import nodes
from bt_meta.bt.nodes.base import PortValue, PortValueError
from bt_meta.bt.nodes.parallel import ParallelThresholdError, threshold
from bt_meta.bt.nodes.ticking import install_wake_up, tick_exactly_once, tick_once
from bt_meta.bt.registry import (
    NodeInstance,
    NodeRegistry,
    NodeType,
    PortError,
    PortSpec,
    RegistryError,
    UnknownNodeError,
    blackboard_key,
    default_registry,
)

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


pytestmark = pytest.mark.usefixtures("clean_blackboard")


class Scripted(py_trees.behaviour.Behaviour):
    """Returns ``script[k]`` on its k-th tick (the last entry repeats); counts ticks, starts and halts."""

    def __init__(self, name: str, *script: Status) -> None:
        super().__init__(name)
        self.script = list(script)
        self.ticks = 0
        self.starts = 0
        self.halts = 0

    def initialise(self) -> None:
        self.starts += 1

    def update(self) -> Status:
        status = self.script[min(self.ticks, len(self.script) - 1)]
        self.ticks += 1
        return status

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING:
            self.halts += 1


def ticks(root, count: int, tick=tick_exactly_once) -> list[Status]:
    return [tick(root) for _ in range(count)]


# ----------------------------------------------------------------------------------------------------- registry


def test_registry_lookup_errors_and_custom_types():
    registry = default_registry()
    assert "Sequence" in registry and "MoveTo" not in registry
    with pytest.raises(UnknownNodeError) as info:
        registry.get("Fallbak")
    assert str(info.value) == "unknown node ID 'Fallbak'; did you mean Fallback, AsyncFallback, ReactiveFallback?"
    assert isinstance(info.value, KeyError)
    assert registry.custom_types() == []
    move = NodeType("MoveTo", "Action", [PortSpec("goal")], lambda **k: Scripted(k["name"], S))
    registry.register(move)
    assert registry.custom_types() == [move]
    with pytest.raises(RegistryError, match="'MoveTo' is already registered"):
        registry.register(move)
    registry.register(move, replace=True)
    assert len(registry) == len(default_registry()) + 1
    assert "MoveTo" not in registry.copy().copy().ids()[:-1] and "MoveTo" in registry.copy()


def test_node_type_validation():
    with pytest.raises(RegistryError, match="category must be one of"):
        NodeType("X", "Leaf", [], lambda **k: None)  # type: ignore[arg-type]
    with pytest.raises(RegistryError, match="not a valid XML"):
        NodeType("has space", "Action", [], lambda **k: None)
    with pytest.raises(RegistryError, match="declares a port twice"):
        NodeType("X", "Action", [PortSpec("a"), PortSpec("a")], lambda **k: None)
    with pytest.raises(RegistryError, match="direction must be one of"):
        PortSpec("a", "sideways")  # type: ignore[arg-type]


def test_port_conversion_and_requiredness():
    assert PortSpec("n", type_name="int").convert(" -3 ") == -3
    assert PortSpec("n", type_name="double").convert("2.5") == 2.5
    assert PortSpec("b", type_name="bool").convert("TRUE") is True
    assert PortSpec("b", type_name="bool").convert("0") is False
    assert PortSpec("s").convert("anything") == "anything"
    with pytest.raises(ValueError, match="port 'n' expects unsigned int, got '-1'"):
        PortSpec("n", type_name="unsigned int").convert("-1")
    with pytest.raises(ValueError, match="port 'b' expects bool, got 'maybe'"):
        PortSpec("b", type_name="bool").convert("maybe")
    assert PortSpec("a").required and not PortSpec("a", default="x").required
    assert not PortSpec("out", "output").required and PortSpec("io", "inout").required
    assert blackboard_key("{goal}") == "goal" and blackboard_key(" { g } ") == "g" and blackboard_key("goal") is None


def test_create_checks_ports_and_children_and_attaches_bt_node():
    registry = default_registry()
    with pytest.raises(PortError, match="missing required port 'num_cycles'"):
        registry.create("Repeat", children=[nodes.AlwaysSuccess()])
    with pytest.raises(RegistryError, match=r"'Inverter' \(Decorator\) needs 1 children, got 2"):
        registry.create("Inverter", children=[nodes.AlwaysSuccess(), nodes.AlwaysFailure()])
    with pytest.raises(RegistryError, match=r"'Sequence' \(Control\) needs at least 1 children, got 0"):
        registry.create("Sequence")
    parallel = registry.create("Parallel", name="both", children=[nodes.AlwaysSuccess()])
    assert parallel.name == "both"
    assert parallel.bt_node == NodeInstance("Parallel", "Control", {})  # defaults are not written back
    assert tick_exactly_once(parallel) == S


def test_an_empty_registry_has_nothing():
    with pytest.raises(UnknownNodeError, match=r"known IDs: $"):
        NodeRegistry().get("Sequence")


# ----------------------------------------------------------------------------------------------------- controls


def test_sequence_restarts_at_zero_after_failure_and_resumes_running_child():
    a, b = Scripted("a", S), Scripted("b", R, F, S)
    seq = nodes.Sequence("s", [a, b])
    assert ticks(seq, 3) == [R, F, S]
    assert (a.ticks, b.ticks) == (2, 3)  # a is not re-ticked while b runs, but is after b's failure


def test_sequence_with_memory_retries_only_the_failed_child_even_after_a_halt():
    a, b = Scripted("a", S), Scripted("b", F, R, S)
    seq = nodes.SequenceWithMemory("s", [a, b])
    assert tick_exactly_once(seq) == F
    assert tick_exactly_once(seq) == R
    seq.stop(Status.INVALID)  # halted while b runs: BT.CPP keeps the index
    assert b.halts == 1
    assert tick_exactly_once(seq) == S
    assert (a.ticks, b.ticks) == (1, 3)


def test_reactive_sequence_rechecks_conditions_and_halts_the_runner():
    guard, work = Scripted("guard", S, S, F), Scripted("work", R)
    seq = nodes.ReactiveSequence("r", [guard, work])
    assert ticks(seq, 3) == [R, R, F]
    assert guard.ticks == 3 and work.ticks == 2 and work.halts == 1


def test_fallback_and_reactive_fallback():
    a, b = Scripted("a", F), Scripted("b", R, S)
    assert ticks(nodes.Fallback("f", [a, b]), 2) == [R, S]
    assert a.ticks == 1
    c, d = Scripted("c", F, S), Scripted("d", R)
    assert ticks(nodes.ReactiveFallback("rf", [c, d]), 2) == [R, S]
    assert d.halts == 1


@pytest.mark.parametrize(("count", "children", "expected"), [(-1, 3, 3), (-2, 3, 2), (-4, 3, 0), (2, 3, 2), (0, 3, 0)])
def test_parallel_threshold_arithmetic(count, children, expected):
    assert threshold(count, children) == expected


def test_parallel_counts_and_does_not_retick_finished_children():
    a, b, c = Scripted("a", S), Scripted("b", R, R, S), Scripted("c", F)
    par = nodes.Parallel("p", [a, b, c], success_count=2, failure_count=2)
    assert ticks(par, 3) == [R, R, S]
    assert (a.ticks, b.ticks, c.ticks) == (1, 3, 1)
    x, y = Scripted("x", F), Scripted("y", R)
    fails = nodes.Parallel("q", [y, x], success_count=-1, failure_count=1)
    assert tick_exactly_once(fails) == F
    assert y.halts == 1
    z = Scripted("z", R)
    # Success becomes impossible after the first failure: the next child is not even ticked.
    assert tick_exactly_once(nodes.Parallel("q", [Scripted("w", F), z], success_count=-1, failure_count=2)) == F
    assert z.ticks == 0


def test_parallel_threshold_from_the_blackboard_is_checked_at_tick_time():
    py_trees.blackboard.Blackboard.set("/need", "5")
    par = nodes.Parallel(
        "p", [nodes.AlwaysSuccess()], success_count=PortValue(PortSpec("success_count", type_name="int"), "{need}")
    )
    with pytest.raises(ParallelThresholdError, match="success_count 5 > 1 children"):
        tick_exactly_once(par)


# ----------------------------------------------------------------------------------------------------- decorators


def test_status_rewriting_decorators_reset_their_child():
    for cls, child_status, expected in [
        (nodes.Inverter, S, F),
        (nodes.Inverter, F, S),
        (nodes.ForceSuccess, F, S),
        (nodes.ForceFailure, S, F),
        (nodes.KeepRunningUntilFailure, S, R),
        (nodes.KeepRunningUntilFailure, F, F),
    ]:
        child = Scripted("c", child_status)
        decorator = cls("d", child)
        assert tick_exactly_once(decorator) == expected, cls.__name__
        assert child.status == Status.INVALID  # reset, as BT.CPP's resetChild
    running = Scripted("r", R)
    assert tick_exactly_once(nodes.Inverter("i", running)) == R


def test_repeat_and_retry_loop_within_one_tick_outside_a_tree():
    child = Scripted("c", S)
    repeat = nodes.Repeat("r", child, 3)
    assert tick_exactly_once(repeat) == S
    assert child.ticks == 3 and child.starts == 3
    flaky = Scripted("f", F, F, S)
    retry = nodes.RetryUntilSuccessful("t", flaky, 5)
    assert tick_exactly_once(retry) == S and flaky.ticks == 3
    hopeless = Scripted("h", F)
    assert tick_exactly_once(nodes.RetryUntilSuccessful("t", hopeless, 4)) == F and hopeless.ticks == 4


def test_repeat_in_a_tree_yields_after_each_synchronous_iteration():
    child = Scripted("c", S)
    repeat = nodes.Repeat("r", child, 3)
    install_wake_up(repeat)
    assert ticks(repeat, 3) == [R, R, S]
    assert child.ticks == 3
    # tick_once re-ticks the root while a node raised the wake-up signal: all three cycles in one call.
    assert tick_once(repeat) == S and child.ticks == 6


def test_repeat_with_an_asynchronous_child_loops_without_yielding():
    child = Scripted("c", R, S, R, S)
    repeat = nodes.Repeat("r", child, 2)
    install_wake_up(repeat)
    # The first cycle finishes on tick 2 (the child was RUNNING before), so the second starts in that same tick.
    assert ticks(repeat, 3) == [R, R, S]
    assert child.ticks == 4


def test_repeat_forever_and_failure():
    child = Scripted("c", S, S, F)
    assert tick_exactly_once(nodes.Repeat("r", child, -1)) == F and child.ticks == 3


def test_timeout_halts_a_slow_child_with_an_injected_clock():
    now = [100.0]
    child = Scripted("slow", R)
    timeout = nodes.Timeout("t", child, 500, clock=lambda: now[0])
    assert tick_exactly_once(timeout) == R
    now[0] += 0.499
    assert tick_exactly_once(timeout) == R
    now[0] += 0.002
    assert tick_exactly_once(timeout) == F
    assert child.halts == 1 and child.ticks == 2
    # It restarts with a fresh deadline.
    assert tick_exactly_once(timeout) == R
    now[0] += 0.4
    assert tick_exactly_once(timeout) == R


def test_timeout_passes_a_fast_child_and_zero_never_expires():
    now = [0.0]
    fast = Scripted("fast", R, S)
    timeout = nodes.Timeout("t", fast, 100, clock=lambda: now[0])
    assert ticks(timeout, 2) == [R, S] and fast.status == Status.INVALID
    never = Scripted("never", R)
    forever = nodes.Timeout("t", never, 0, clock=lambda: now[0])
    tick_exactly_once(forever)
    now[0] += 1e6
    assert tick_exactly_once(forever) == R


def test_subtree_passes_status_through_and_resets():
    child = Scripted("c", R, F)
    subtree = nodes.SubTree("sub", child, "Inner")
    assert ticks(subtree, 2) == [R, F]
    assert child.status == Status.INVALID


# ----------------------------------------------------------------------------------------------------- ports & leaves


def test_port_values_from_the_blackboard():
    spec = PortSpec("n", type_name="int")
    value = PortValue(spec, "{n}")
    with pytest.raises(PortValueError, match="blackboard entry '/n' does not exist"):
        value.get()
    py_trees.blackboard.Blackboard.set("/n", "7")
    assert value.get() == 7
    py_trees.blackboard.Blackboard.set("/n", 9)
    assert value.get() == 9
    py_trees.blackboard.Blackboard.set("/n", "x")
    with pytest.raises(PortValueError, match="port 'n' expects int, got 'x'"):
        value.get()
    with pytest.raises(PortValueError, match="must be a \\{key\\}"):
        PortValue(spec, "3").set(4)
    assert PortValue(spec, "3").get() == 3


def test_set_blackboard_copies_literals_and_entries():
    registry = default_registry()
    first = registry.create("SetBlackboard", ports={"value": "hello", "output_key": "a"})
    second = registry.create("SetBlackboard", ports={"value": "{a}", "output_key": "{b}"})
    assert tick_exactly_once(nodes.Sequence("s", [first, second])) == S
    assert py_trees.blackboard.Blackboard.get("/b") == "hello"


def test_nodes_run_under_a_py_trees_behaviour_tree():
    guard, work = Scripted("guard", S, F), Scripted("work", R)
    tree = py_trees.trees.BehaviourTree(nodes.ReactiveSequence("root", [guard, work]))
    tree.tick()
    assert tree.root.status == R
    tree.tick()
    assert tree.root.status == F and work.halts == 1


def test_py_trees_children_are_halted_only_when_running():
    inner = py_trees.composites.Sequence("inner", memory=True, children=[Scripted("x", S)])
    runner = Scripted("r", R)
    seq = nodes.Sequence("s", [inner, runner])
    assert tick_exactly_once(seq) == R
    seq.stop(Status.INVALID)
    assert runner.halts == 1 and inner.status == Status.INVALID and runner.status == Status.INVALID
