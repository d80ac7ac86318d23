"""``bt-meta run --world ros2 --record-mcap``: the run's joint states, object poses and trajectory goals, and the
tree's statuses, failures and repairs, read back with the MCAP ROS 2 reader; without ROS 2 the option is refused
before anything is built."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from bt_meta.cli import main

ROOT = Path(__file__).resolve().parents[2]
LETTERS = "trees/letters.yaml"
MAGNETIC = "trees/magnetic_attach.yaml"


def test_record_mcap_needs_the_ros2_world(capsys, tmp_path):
    letters = str(ROOT / LETTERS)
    assert main(["run", letters, "--problem", "A", "--record-mcap", str(tmp_path / "run.mcap")]) == 2
    assert "--record-mcap records the ROS 2 messages of a run: it needs --world ros2" in capsys.readouterr().err
    assert not (tmp_path / "run.mcap").exists()


@pytest.mark.slow
def test_a_ros_driven_run_reads_back_from_its_mcap_file(serve, tmp_path):
    """A repaired run (a goal the controller aborts, retried): robot messages, and the tree's statuses, failure and
    repair."""
    pytest.importorskip("mcap_ros2", reason="needs mcap-ros2-support (the [ros2] extra)")
    from mcap_ros2.reader import read_ros2_messages

    from bt_meta.ros2.mcap_recording import FAILURE_TOPIC, REPAIR_TOPIC, TREE_TOPIC

    path = tmp_path / "run.mcap"
    served = serve("--scene", "magnetic_attach", "--fault", "abort@5")
    done = served.run("run", MAGNETIC, "--problem", "nominal", "--repair", "--memory", str(tmp_path / "memory.sqlite"),
                      "--world", "ros2", "--record-mcap", str(path), "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout)
    assert [f["kind"] for f in report["failures"]] == ["physical"] and len(report["attempts"]) == 1
    ticks = report["ticks"]
    topics: Counter[str] = Counter()
    schemas = {}
    goals = []
    joints = None
    tree, failures, repairs = [], [], []
    for message in read_ros2_messages(str(path)):
        topic = message.channel.topic
        topics[topic] += 1
        schemas[topic] = message.schema.name
        if topic.endswith("/goal_trajectory"):
            goals.append(message.ros_msg)
        elif topic == "/joint_states":
            joints = message.ros_msg
        elif topic in (TREE_TOPIC, FAILURE_TOPIC, REPAIR_TOPIC):
            {TREE_TOPIC: tree, FAILURE_TOPIC: failures, REPAIR_TOPIC: repairs}[topic].append(
                json.loads(message.ros_msg.data))
    action = "/right_arm_controller/follow_joint_trajectory/goal_trajectory"
    assert schemas["/joint_states"] == "sensor_msgs/msg/JointState"
    assert schemas["/bt_meta/object_poses"] == "visualization_msgs/msg/MarkerArray"
    assert schemas[action] == "trajectory_msgs/msg/JointTrajectory"
    # one goal per advanced tick; a few skills advance the world outside the tree's ticks (so at least as many)
    assert topics[action] + topics.get("/left_arm_controller/follow_joint_trajectory/goal_trajectory", 0) >= ticks
    assert topics["/joint_states"] >= ticks  # a fresh state after every goal, and the served rate besides
    assert list(goals[0].joint_names) == ["right_s0", "right_s1", "right_e0", "right_e1", "right_w0", "right_w1",
                                          "right_w2"]
    assert len(goals[0].points) == 1 and len(goals[0].points[0].positions) == 7
    assert "left_s0" in joints.name and len(joints.position) == len(joints.name)
    # what the tree did: a status record per tick of every segment, the failure, the applied repair
    assert {schemas[t] for t in (TREE_TOPIC, FAILURE_TOPIC, REPAIR_TOPIC)} == {"std_msgs/msg/String"}
    assert len(tree) == ticks and tree[-1]["status"] == "SUCCESS"
    assert all(record["nodes"] and record["nodes"][-1][1] == record["status"] for record in tree)  # the root last
    assert [f["failure"]["kind"] for f in failures] == [f["kind"] for f in report["failures"]]
    assert [r["outcome"] for r in repairs if r["outcome"] == "applied"] == ["applied"] * len(report["attempts"])

class _Run:
    """The part of a run context the tree log wraps: ``tick(root, visit)`` and ``tick_count``."""

    def __init__(self) -> None:
        self.tick_count = 0

    def tick(self, root, visit=None):
        self.tick_count += 1
        for behaviour in root.tick():
            if visit is not None:
                visit(behaviour)
        return root.status


def test_the_tree_log_writes_statuses_failures_and_repairs_as_ros2_strings(tmp_path):
    pytest.importorskip("mcap_ros2", reason="needs mcap-ros2-support (the [ros2] extra)")
    pytest.importorskip("std_msgs.msg", reason="needs the [ros2] extra")
    import py_trees
    from mcap_ros2.reader import read_ros2_messages

    from bt_meta.ros2.mcap_recording import FAILURE_TOPIC, REPAIR_TOPIC, TREE_TOPIC, McapRecording, McapTreeLog

    path = tmp_path / "tree.mcap"
    recording = McapRecording(path)
    log = McapTreeLog(recording)
    run = _Run()
    log.watch(run)
    log.watch(run)  # once per run: a second watch does not log each tick twice
    root = py_trees.composites.Sequence("Root", memory=True, children=[
        py_trees.behaviours.Running("Busy"), py_trees.behaviours.Success("Done")])
    visited = []
    assert run.tick(root, visited.append) == py_trees.common.Status.RUNNING
    assert [b.name for b in visited] == ["Busy", "Root"]  # the caller's visit still sees every node
    log.bt_meta_trace_event({"type": "failure", "tick": 1, "failure": {"kind": "physical", "message": "dropped"}})
    log.bt_meta_trace_event({"type": "repair", "tick": 1, "outcome": "applied", "attempt": {"number": 1}})
    log.bt_meta_trace_event({"type": "step_end", "tick": 1})  # not a failure or repair: not written
    recording.close()

    read = [(m.channel.topic, m.schema.name, json.loads(m.ros_msg.data)) for m in read_ros2_messages(str(path))]
    assert {schema for _, schema, _ in read} == {"std_msgs/msg/String"}
    assert [(topic, record) for topic, _, record in read] == [
        (TREE_TOPIC, {"tick": 1, "status": "RUNNING", "nodes": [["Busy", "RUNNING"], ["Root", "RUNNING"]]}),
        (FAILURE_TOPIC, {"tick": 1, "failure": {"kind": "physical", "message": "dropped"}}),
        (REPAIR_TOPIC, {"tick": 1, "outcome": "applied", "attempt": {"number": 1}}),
    ]
