"""The tick-by-tick harness and its pytest fixtures."""

from __future__ import annotations

import pytest
from py_trees.common import Status

from bt_meta.bt.context import FAILURES_KEY, STATE_KEY, WORLD_KEY
from bt_meta.plugins import hookimpl
from bt_meta.testing import HarnessError, TreeHarness, clear_blackboard

TASKS = """
domain:
  name: lamp
  predicates:
    off: []
    on: []
  primitives:
    switch_on:
      parameters: []
      precondition: off()
      add: [on()]
      delete: [off()]
    switch_off:
      parameters: []
      precondition: on()
      add: [off()]
      delete: [on()]
  tasks:
    blink: []
  methods:
    - name: blink_once
      task: blink()
      precondition: off()
      subtasks: [switch_on(), switch_off()]
problems:
  dark:
    init: [off()]
    tasks: [blink()]
"""

XML = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence name="root">
      <switch_on name="n1 switch_on()"/>
      <AlwaysSuccess name="pause"/>
      <switch_off name="n2 switch_off()" _monitor="false"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


def test_tick_by_tick_statuses_and_history(bt_harness):
    h = bt_harness(TASKS, "dark", ticks_per_skill=2)
    assert h.tick() is Status.RUNNING
    assert h.statuses() == {"n0 guard blink_once": "SUCCESS", "n1 switch_on()": "RUNNING",
                            "Monitor<n1 switch_on()>": "RUNNING", "n0 blink()": "RUNNING", "plan dark": "RUNNING"}
    assert h.status("n1") is Status.RUNNING and h.status("n2") is Status.INVALID
    assert h.tick_n(1) == [Status.RUNNING]  # switch_on finishes, switch_off starts in the same tick
    assert h.statuses()["n1 switch_on()"] == "SUCCESS" and h.status("n2") is Status.RUNNING
    assert h.tick_until(Status.SUCCESS) is Status.SUCCESS
    assert [entry["status"] for entry in h.history] == [Status.RUNNING] * 2 + [Status.SUCCESS]
    assert h.statuses(tick=1)["n1 switch_on()"] == "RUNNING"
    assert h.blackboard(STATE_KEY) is h.state and ("off",) in h.state
    assert h.blackboard(WORLD_KEY) is h.world and h.blackboard(FAILURES_KEY) == []


def test_tick_until_a_predicate_and_an_unreached_status(bt_harness):
    h = bt_harness(TASKS, "dark", ticks_per_skill=3)
    h.tick_until(lambda harness: harness.status("n2") is Status.RUNNING)
    assert ("on",) in h.state
    with pytest.raises(HarnessError, match="not reached after 2 ticks"):
        h.tick_until("FAILURE", max_ticks=2)
    with pytest.raises(HarnessError, match="unknown status 'DONE!'"):
        h.tick_until("DONE!")


def test_unknown_node_and_blackboard_key_errors(bt_harness):
    h = bt_harness(TASKS, "dark")
    with pytest.raises(HarnessError, match="no node named 'n9'"):
        h.node("n9")
    with pytest.raises(HarnessError, match="no blackboard entry '/nothing'"):
        h.blackboard("nothing")


def test_recorded_failures_and_kinds(bt_harness):
    h = bt_harness(TASKS, "dark", faults=["switch_off=fail:physical"])
    assert h.tick_until() is Status.FAILURE
    assert h.failure_kinds == ["physical"]
    assert h.failures[0].node_id == "n2" and h.blackboard(FAILURES_KEY)[0]["kind"] == "physical"


def test_xml_with_an_opted_out_action(bt_harness, tmp_path):
    (tmp_path / "lamp.yaml").write_text(TASKS)
    (tmp_path / "lamp.xml").write_text(XML)
    h = bt_harness(tmp_path / "lamp.xml", "dark")
    assert h.tick() is Status.SUCCESS
    assert getattr(h.node("n1 switch_on()").__class__, "is_monitor", False)
    assert h.node("n2 switch_off()").__class__.__name__ == "PrimitiveAction"  # no monitor around it
    assert h.status("pause") is Status.SUCCESS


def test_unmonitored_action_records_its_own_failure(bt_harness, tmp_path):
    (tmp_path / "lamp.yaml").write_text(TASKS)
    (tmp_path / "lamp.xml").write_text(XML)
    h = bt_harness(tmp_path / "lamp.xml", "dark", faults=["switch_off=fail:collision"])
    assert h.tick() is Status.FAILURE
    assert h.failure_kinds == ["collision"]


def test_trace_plugin_that_raises_is_recorded_and_the_run_goes_on(bt_harness):
    class BrokenTrace:
        @hookimpl
        def bt_meta_trace_event(self, event):
            raise OSError("disk full")

    h = bt_harness(TASKS, "dark", extra_plugins=[("broken_trace", BrokenTrace())])
    assert h.tick_until() is Status.SUCCESS
    assert h.failures and {f.kind.value for f in h.failures} == {"internal"}
    assert h.failures[0].plugin == "broken_trace" and "disk full" in h.failures[0].evidence["error"]


def test_unknown_world_is_reported(tmp_path):
    (tmp_path / "lamp.yaml").write_text(TASKS)
    with pytest.raises(HarnessError, match="no plugin provides a world named 'mars'"):
        TreeHarness.from_file(tmp_path / "lamp.yaml", world="mars")
    clear_blackboard()


def test_plugins_fixture(bt_plugins):
    class Mine:
        @hookimpl
        def bt_meta_observe(self, world):
            return None

    host = bt_plugins(("mine", Mine()), entry_points=False)
    assert host.plugin_names() == ["fake_world", "lazy_worlds", "mine"]


def test_world_plugins_get_the_task_file_and_options(tmp_path, bt_blackboard):
    from bt_meta.world.fake import FakeWorld

    seen = {}

    class Probe:
        @hookimpl
        def bt_meta_make_world(self, name, domain, problem, options):
            if name != "probe":
                return None
            seen.update(options)
            return FakeWorld(domain, problem)

    (tmp_path / "lamp.yaml").write_text(TASKS)
    h = TreeHarness.from_file(tmp_path / "lamp.yaml", world="probe", world_options={"seed": 7, "variant": "x"},
                              extra_plugins=[("probe", Probe())])
    assert h.tick() is Status.SUCCESS
    assert seen["task_file"].endswith("lamp.yaml") and seen["seed"] == 7 and seen["variant"] == "x"
    assert seen["faults"] == [] and seen["ticks_per_skill"] == 1
    h.close()
