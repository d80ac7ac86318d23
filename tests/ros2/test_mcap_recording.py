"""``bt-meta run --world ros2 --record-mcap``: the run's joint states, object poses and trajectory goals, read back
with the MCAP ROS 2 reader; without ROS 2 the option is refused before anything is built."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from bt_meta.cli import main

LETTERS = "trees/letters.yaml"
START = ("--joint", "left_s0=0.8")


def test_record_mcap_needs_the_ros2_world(capsys, tmp_path):
    letters = str(Path(__file__).resolve().parents[2] / LETTERS)
    assert main(["run", letters, "--problem", "A", "--record-mcap", str(tmp_path / "run.mcap")]) == 2
    assert "--record-mcap records the ROS 2 messages of a run: it needs --world ros2" in capsys.readouterr().err
    assert not (tmp_path / "run.mcap").exists()


@pytest.mark.slow
def test_a_ros_driven_run_reads_back_from_its_mcap_file(serve, tmp_path):
    pytest.importorskip("mcap_ros2", reason="needs mcap-ros2-support (the [ros2] extra)")
    from mcap_ros2.reader import read_ros2_messages

    path = tmp_path / "run.mcap"
    served = serve("--scene", "letters_A", *START)
    done = served.run("run", LETTERS, "--problem", "A", "--world", "ros2", "--record-mcap", str(path), "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    ticks = json.loads(done.stdout)["ticks"]
    topics: Counter[str] = Counter()
    schemas = {}
    goals = []
    joints = None
    for message in read_ros2_messages(str(path)):
        topics[message.channel.topic] += 1
        schemas[message.channel.topic] = message.schema.name
        if message.channel.topic.endswith("/goal_trajectory"):
            goals.append(message.ros_msg)
        elif message.channel.topic == "/joint_states":
            joints = message.ros_msg
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
