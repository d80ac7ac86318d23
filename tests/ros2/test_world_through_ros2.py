"""The proof by difference: the served simulator in one process, ``bt-meta run --world ros2`` in another (each in
a loopback-only network namespace, real rclpy), end as the in-process run does, object poses within 1 mm."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
BT_META = [sys.executable, "-m", "bt_meta.cli"]

LETTERS = "trees/letters.yaml"
START = ("--joint", "left_s0=0.8")  # the letters grounding's robot_pose for the Baxter


def _in_process(*args: str) -> dict:
    done = subprocess.run([*BT_META, *args, "--json"], cwd=ROOT, capture_output=True, text=True, check=False)
    return json.loads(done.stdout)


def _poses_within(ros: dict, local: dict, tolerance: float = 1e-3) -> float:
    assert set(ros["objects"]) == set(local["objects"])
    worst = max(float(np.linalg.norm(np.subtract(ros["objects"][n]["pose"][:3], local["objects"][n]["pose"][:3])))
                for n in local["objects"])
    assert worst < tolerance, f"object poses differ by {worst * 1000:.3f} mm"
    return worst


@pytest.mark.slow
def test_letter_a_through_ros2_ends_as_in_process(serve):
    served = serve("--scene", "letters_A", *START)
    done = served.run("run", LETTERS, "--problem", "A", "--world", "ros2", "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "without any feedback" not in done.stderr  # the served controller sends feedback: no false alarm
    ros = json.loads(done.stdout)
    local = _in_process("run", LETTERS, "--problem", "A")
    assert ros["status"] == local["status"] == "SUCCESS"
    assert ros["plan"] == local["plan"] and ros["ticks"] == local["ticks"]
    _poses_within(ros, local)
    assert served.stop() == 0  # SIGTERM: a clean stop
    assert "bt-meta sim: stopped" in served.log.read_text()


@pytest.mark.slow
def test_a_repaired_variant_through_ros2_matches_its_in_process_run(serve, tmp_path):
    memory = tmp_path / "memory.sqlite"
    recorded = subprocess.run([*BT_META, "record", LETTERS, "--problem", "A", "--memory", str(memory)], cwd=ROOT,
                              capture_output=True, text=True, check=False)
    assert recorded.returncode == 0, recorded.stderr
    local_memory, ros_memory = tmp_path / "local.sqlite", tmp_path / "ros.sqlite"
    shutil.copy(memory, local_memory)
    shutil.copy(memory, ros_memory)
    variant = "A_two_1x1_same_colour"
    args = ("run", LETTERS, "--problem", "A", "--variant", variant, "--repair")
    local = _in_process(*args, "--memory", str(local_memory))
    served = serve("--scene", "letters_A", "--variant", variant, *START)
    done = served.run(*args, "--memory", str(ros_memory), "--world", "ros2", "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    ros = json.loads(done.stdout)
    assert ros["status"] == local["status"] == "SUCCESS"
    assert [f["kind"] for f in ros["failures"]] == [f["kind"] for f in local["failures"]] == ["unknown_entity"]
    assert len(ros["attempts"]) == len(local["attempts"]) and ros["ticks"] == local["ticks"]
    assert [r["changes"] for r in ros["repairs"]] == [r["changes"] for r in local["repairs"]]
    assert ros["refinement_saved"]["subtasks"] == local["refinement_saved"]["subtasks"]
    _poses_within(ros, local)


@pytest.mark.slow
def test_tick_acts_through_ros2_too_and_exits_cleanly(serve):
    served = serve("--scene", "letters_A", *START)
    done = served.run("tick", LETTERS, "--problem", "A", "--world", "ros2", "--ticks", "2000", "--json")
    assert done.returncode == 0, done.stderr[-2000:]  # tick never closes its world: the connection closes at exit
    assert json.loads(done.stdout)["status"] == "SUCCESS"
