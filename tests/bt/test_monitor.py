"""The Monitor: precondition checks, expectation mismatches, skill failures, contained plugin errors."""

from __future__ import annotations

import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.context import FAILURES_KEY, STATE_KEY
from bt_meta.bt.expectations import Comparison, Expectation
from bt_meta.bt.failures import FailureKind
from bt_meta.bt.monitor import Monitor
from bt_meta.plugins import hookimpl

DOMAIN = """
domain:
  name: blocks
  types: [block, cell]
  predicates:
    on_table: [block]
    at: [block, cell, cell]
    hand_empty: []
    held: [block]
  primitives:
    pick:
      parameters: [?b - block]
      precondition: on_table(?b) and hand_empty()
      add: [held(?b)]
      delete: [on_table(?b), hand_empty()]
    put:
      parameters: [?b - block, ?x - cell, ?y - cell]
      precondition: held(?b)
      add: [at(?b, ?x, ?y), hand_empty()]
      delete: [held(?b)]
  tasks:
    place: [?b - block, ?x - cell, ?y - cell]
    draw: []
  methods:
    - name: place_by_pick_put
      task: place(?b, ?x, ?y)
      precondition: on_table(?b)
      subtasks: [pick(?b), put(?b, ?x, ?y)]
    - name: draw_two
      task: draw()
      precondition: on_table(?a) and on_table(?c) and ?a != ?c
      subtasks: [place(?a, 0, 0), place(?c, 1, 0)]
problems:
  two:
    objects: {block: [b0, b1], cell: [0, 1]}
    init: [on_table(b0), on_table(b1), hand_empty()]
    tasks: [draw()]
"""


@pytest.fixture
def harness(bt_harness):
    def make(**options):
        return bt_harness(DOMAIN, "two", **options)

    return make


def test_nominal_run_succeeds_without_failures(harness):
    h = harness(ticks_per_skill=3)
    assert h.tick() is Status.RUNNING
    assert h.status("n2") is Status.RUNNING
    assert h.tick_until("done", max_ticks=50) is Status.SUCCESS
    assert h.failures == []
    # 4 skills x 3 skill ticks; a skill finishing lets the next one start in the same tree tick.
    assert h.world.total_ticks == 12 and h.run.tick_count == 9
    assert ("at", "b0", "0", "0") in h.state and ("at", "b1", "1", "0") in h.state
    assert py_trees.blackboard.Blackboard.storage[STATE_KEY] is h.state
    assert py_trees.blackboard.Blackboard.storage[FAILURES_KEY] == []


def test_silent_effect_is_caught_by_the_symbolic_expectation(harness):
    h = harness(faults=["put(b0, 0, 0)=silent"])
    assert h.tick_until("done") is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.UNEXPECTED_CONFIGURATION
    assert (failure.node_id, failure.step, failure.action, failure.args) == ("n3", 1, "put", ("b0", "0", "0"))
    mismatch = failure.evidence["mismatches"][0]
    assert mismatch["plugin"] == "symbolic_expectations"
    assert mismatch["evidence"]["missing"] == ["at(b0, 0, 0)", "hand_empty()"]
    assert mismatch["evidence"]["not_deleted"] == ["held(b0)"]
    assert h.status("n3") is Status.FAILURE
    assert h.status("n3", raw=True) is Status.SUCCESS  # the skill said SUCCESS; the monitor disagreed
    # The belief state adopts the observation, so a replanner sees the truth.
    assert ("held", "b0") in h.state
    record = py_trees.blackboard.Blackboard.storage[FAILURES_KEY][0]
    assert record["kind"] == "unexpected_configuration" and record["node_id"] == "n3"


def test_silent_effect_goes_unnoticed_without_expectation_plugins(harness):
    # Only the fake world (no perception, no expectations): the monitor applies the expected effects.
    h = harness(faults=["put(b0, 0, 0)=silent"], entry_points=False)
    status = h.tick_until("done")
    # The belief is wrong, so the next pick's precondition holds in belief but not in the world.
    assert status is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.PRECONDITION and failure.action == "pick"
    assert "does not hold in the true state" in failure.message


def test_skill_failure_records_its_kind(harness):
    h = harness(faults=["pick(b1)=fail:physical"])
    assert h.tick_until("done") is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.PHYSICAL
    assert failure.node_id == "n5" and failure.step == 2
    assert failure.evidence["skill"]["fault"] == "fail"


def test_skill_that_raises_is_an_internal_failure_not_a_crash(harness):
    h = harness(faults=["put=raise"])
    assert h.tick_until("done") is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.INTERNAL
    assert "RuntimeError" in failure.message and "traceback" in failure.evidence


def test_precondition_failure_does_not_start_the_child(harness):
    h = harness()
    h.world.apply_symbolic(add=[], delete=[("hand_empty",)])
    h.run.state = h.world.symbolic_state()
    assert h.tick() is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.PRECONDITION
    assert failure.action == "pick" and failure.node_id == "n2"
    assert failure.evidence["state"] == ["on_table(b0)", "on_table(b1)"]
    assert "hand_empty()" in failure.evidence["condition"]
    assert h.world.executed == []  # no skill started
    assert h.status("n2", raw=True) is Status.INVALID


def test_method_guard_failure_is_recorded_with_its_node(harness):
    h = harness()
    h.run.state = h.run.state.apply(delete=[("on_table", "b0")])
    assert h.tick() is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.PRECONDITION and failure.node_id == "n0"
    assert "draw_two" in failure.message


class Raising:
    def __init__(self, hook: str) -> None:
        self.hook = hook

    @hookimpl
    def bt_meta_observe(self, world, context):
        if self.hook == "observe" and context.action == "put":
            raise ValueError("camera unplugged")
        return None

    @hookimpl
    def bt_meta_compare(self, expectation, observations, context):
        if self.hook == "compare":
            raise KeyError("boom")
        return None


@pytest.mark.parametrize("hook", ["observe", "compare"])
def test_plugin_that_raises_fails_the_node_as_internal_and_the_tree_keeps_ticking(harness, hook):
    h = harness(extra_plugins=[("raising", Raising(hook))])
    assert h.tick_until("done") is Status.FAILURE
    failure = h.failures[0]
    assert failure.kind is FailureKind.INTERNAL
    assert failure.plugin == "raising"
    assert failure.evidence["hook"] == f"bt_meta_{hook}"
    assert ("camera unplugged" if hook == "observe" else "boom") in failure.evidence["error"]
    # The tree is still usable: it ticks again (and fails again the same way), nothing propagated.
    assert h.tick_until("done") is Status.FAILURE
    assert len(h.failures) >= 2


class Counting:
    """Observes by counting its calls and what the world had done by then; compares nothing."""

    def __init__(self) -> None:
        self.calls: list[tuple[str | None, int]] = []

    @hookimpl
    def bt_meta_observe(self, world, context):
        self.calls.append((context.action, len(world.executed)))
        return {"call": len(self.calls)}

    @hookimpl
    def bt_meta_compare(self, expectation, observations, context):
        return None


def test_the_run_keeps_what_was_observed_before_its_first_step_started(harness):
    """``RunContext.start_observations``: the observe plugins called once before the first step runs (the world as
    the run found it, for comparisons that must tell what was already there), then after each step."""
    counting = Counting()
    h = harness(extra_plugins=[("counting", counting)])
    assert h.run.start_observations is None
    assert h.tick_until("done") is Status.SUCCESS
    assert h.run.start_observations["call"] == 1
    assert counting.calls[0] == ("pick", 0)  # before anything ran
    assert [n for _, n in counting.calls[1:]] == [1, 2, 3, 4]  # then after each of the four steps


class Classifier:
    @hookimpl(tryfirst=True)
    def bt_meta_classify_failure(self, failure, mismatches, context):
        return "verification" if mismatches else None


class Notes:
    @hookimpl
    def bt_meta_on_failure(self, failure, context):
        return {"seen": failure.kind.value}


def test_classification_hook_and_meta_reasoner_notes(harness):
    h = harness(faults=["put(b1, 1, 0)=silent"], extra_plugins=[("classifier", Classifier()), ("notes", Notes())])
    assert h.tick_until("done") is Status.FAILURE
    [failure] = h.failures
    assert failure.kind is FailureKind.VERIFICATION
    assert failure.evidence["classified_by"] == "classifier"
    assert failure.evidence["meta"]["notes"] == {"seen": "verification"}
    assert py_trees.blackboard.Blackboard.storage[FAILURES_KEY][0]["evidence"]["meta"]["notes"]["seen"] == (
        "verification")


class CustomExpectation:
    @hookimpl
    def bt_meta_expectations(self, context):
        return [Expectation(kind="colour", description=f"{context.action} keeps colours")]

    @hookimpl
    def bt_meta_compare(self, expectation, observations, context):
        if expectation.kind != "colour":
            return None
        return Comparison(matched=context.action != "put", message="colour changed", evidence={"seen": "red"})


def test_custom_expectation_kind_and_trace_events(harness):
    events = []

    class Tracer:
        @hookimpl
        def bt_meta_trace_event(self, event):
            events.append(event)

    h = harness(extra_plugins=[("custom", CustomExpectation()), ("tracer", Tracer())])
    assert h.tick_until("done") is Status.FAILURE
    [failure] = h.failures
    assert failure.action == "put" and failure.message == "colour changed"
    types = [e["type"] for e in events]
    assert types[:3] == ["run_start", "step_start", "step_end"] and "failure" in types and types[-1] == "tick"
    assert events[0]["problem"] == "two" and "on_table b0" in events[0]["state"]
    h.run.finish(h.root.status)
    assert events[-1] == {"type": "run_end", "tick": 1, "status": "FAILURE", "ticks": 1, "failures": 1}
    end = next(e for e in events if e["type"] == "step_end")
    assert end["action"] == "pick" and end["status"] == "SUCCESS" and "held(b0)" in end["state"]


def test_monitor_without_a_run_just_relays():
    child = py_trees.behaviours.Success(name="leaf")
    monitor = Monitor(child)
    monitor.tick_once()
    assert monitor.status is Status.SUCCESS and monitor.is_monitor


EXTERNAL = """
domain:
  name: reach
  predicates:
    on_table: [block]
    held: [block]
  external:
    reachable: [block]
  primitives:
    grab:
      parameters: [?b]
      precondition: on_table(?b) and reachable(?b)
      add: [held(?b)]
      delete: [on_table(?b)]
problems:
  one:
    init: [on_table(b0)]
    tasks: [grab(b0)]
"""


class Reach:
    def __init__(self) -> None:
        self.answer: bool | Exception = True

    @hookimpl
    def bt_meta_external_predicate(self, name, args, state):
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer if name == "reachable" else None


def test_external_predicates_in_preconditions_come_from_plugins(bt_harness):
    reach = Reach()
    h = bt_harness(EXTERNAL, "one", extra_plugins=[("reach", reach)])
    assert h.tick() is Status.SUCCESS and h.failures == []
    reach.answer = False
    h.world.apply_symbolic(add=[("on_table", "b0")], delete=[("held", "b0")])
    h.run.state = h.world.symbolic_state()
    assert h.tick() is Status.FAILURE
    assert h.failure_kinds == ["precondition"]
    reach.answer = ConnectionError("IK server down")
    assert h.tick() is Status.FAILURE
    failure = h.failures[-1]
    assert failure.kind is FailureKind.INTERNAL and failure.plugin == "reach"
    assert "IK server down" in failure.message


CUPS = """
domain:
  name: cups
  predicates:
    on: [cup, place]
    free: [place]
  primitives:
    move:
      parameters: [?c, ?to]
      precondition: on(?c, ?from) and free(?to)
      add: [on(?c, ?to), free(?from)]
      delete: [on(?c, ?from), free(?to)]
problems:
  one:
    init: [on(c1, shelf), free(table)]
    tasks: [move(c1, table)]
"""


@pytest.mark.parametrize("tracing", [False, True])
def test_effects_bound_by_the_precondition_are_expected(bt_harness, tracing):
    class Tracer:
        @hookimpl
        def bt_meta_trace_event(self, event):
            pass

    extra = [("tracer", Tracer())] if tracing else []
    h = bt_harness(CUPS, "one", faults=["move=silent"], extra_plugins=extra)
    assert h.tick() is Status.FAILURE
    [failure] = h.failures
    evidence = failure.evidence["mismatches"][0]["evidence"]
    assert evidence["missing"] == ["on(c1, table)", "free(shelf)"]
    assert evidence["not_deleted"] == ["on(c1, shelf)", "free(table)"]
