"""The custom repair plugin example: loaded from the project's plugins folder, its proposal repairs the run."""

from __future__ import annotations

from pathlib import Path

from bt_meta_plugins import classification_rules, ground_truth_perception, retry_repair, symbolic_expectations

from bt_meta.meta import run_task_file
from bt_meta.plugins import create_plugin_host

HERE = Path(__file__).resolve().parent
TASK_FILE = HERE / "two_arms.yaml"
SHIPPED = [("ground_truth_perception", ground_truth_perception), ("symbolic_expectations", symbolic_expectations),
           ("classification_rules", classification_rules), ("retry_repair", retry_repair)]


def _host():
    # The project plugins folder (plugins/ next to the task file) is found from the task file alone.
    return create_plugin_host(project_file=TASK_FILE, entry_points=False, plugins=SHIPPED)


def test_the_plugin_file_is_loaded_from_the_project_folder(bt_blackboard):
    host = _host()
    assert "swap_arm_repair" in host.plugin_names()
    assert Path(host.sources["swap_arm_repair"]) == HERE / "plugins" / "swap_arm_repair.py"
    assert host.hooks_of("swap_arm_repair") == ["bt_meta_propose_repairs"]


def test_its_proposal_is_applied_and_repairs_the_run(bt_blackboard):
    # The left gripper never holds the block: retrying cannot help, the other arm can.
    report = run_task_file(TASK_FILE, "stack", plugins=_host(), faults=["pick(left, red)=fail:physical"])
    assert report.ok, report.stop_reason
    assert [(a.proposal["plugin"], a.proposal["action"]) for a in report.attempts] == [
        ("swap_arm_repair", "substitute")]
    assert report.attempts[0].change == "substitute left -> right in 2 step(s)"
    assert report.plan == [["pick", "right", "red"], ["place", "right", "red", "tower"]]


def test_without_the_plugin_the_baseline_gives_up(bt_blackboard):
    host = create_plugin_host(entry_points=False, plugins=SHIPPED)
    report = run_task_file(TASK_FILE, "stack", plugins=host, faults=["pick(left, red)=fail:physical"])
    assert not report.ok
    assert all(a.proposal["plugin"] == "retry_repair" for a in report.attempts)
