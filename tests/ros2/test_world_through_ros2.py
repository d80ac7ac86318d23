"""The proof by difference: the served simulator in one process, ``bt-meta run --world ros2`` in another (each in
a loopback-only network namespace, real rclpy), end as the in-process run does, object poses within 1 mm."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bt_meta.cli import main

from .conftest import REASON

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
@pytest.mark.skipif(REASON is not None, reason=REASON or "")
def test_a_repaired_variant_through_ros2_ends_as_in_process(tmp_path):
    """The proof by difference on a subset: a magnetic variant, repaired, whose join the world's model must learn
    from the robot; each way on its own fresh memory recorded that way. (One variant: the whole comparison takes
    minutes; docs/benchmarks.md has it.)"""
    out = tmp_path / "compare"
    done = subprocess.run([*BT_META, "experiment", "ros2-compare", "--quick", "--generated", "0", "--variants",
                           "magnetic/active_on_side", "--out", str(out), "--json"],
                          cwd=ROOT, capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    result = json.loads(done.stdout)
    assert result == json.loads((out / "comparison.json").read_text())
    summary = result["summary"]
    assert summary["demonstrations"] == summary["demonstrations_alike"] == 1  # the magnetic nominal
    assert summary["variants"] == summary["alike"] == summary["same_ticks"] == 1
    [row] = result["variants"]
    assert row["in_process"] == row["ros2"] and row["in_process"]["status"] == "SUCCESS"
    assert row["in_process"]["failure_kinds"] == ["unexpected_configuration"] and row["in_process"]["attempts"] == 1
    assert row["in_process"]["refinement"]  # repaired, and the repair learned
    assert row["pose_difference_mm"] < 1.0


@pytest.mark.parametrize(("argv", "message"), [
    (["--generated", "-1"], "--generated must be between 0 and 200"),
    (["--families", "nowhere"], "unknown nowhere"),
    (["--variants", "letters/no_such"], "no demo variant letters/no_such"),
])
def test_compare_refuses_bad_arguments_before_anything_starts(capsys, argv, message):
    assert main(["experiment", "ros2-compare", *argv]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_tick_acts_through_ros2_too_and_exits_cleanly(serve):
    served = serve("--scene", "magnetic_attach")  # the shortest task (52 ticks): the letter is drawn above
    done = served.run("tick", "trees/magnetic_attach.yaml", "--problem", "nominal", "--world", "ros2", "--ticks",
                      "2000", "--json")
    assert done.returncode == 0, done.stderr[-2000:]  # tick never closes its world: the connection closes at exit
    assert json.loads(done.stdout)["status"] == "SUCCESS"


def _report(status="SUCCESS", kinds=("unknown_entity",), attempts=1, subtasks=("MoveTo(a)",), x=0.5):
    return {"status": status, "failures": [{"kind": k} for k in kinds], "attempts": [{}] * attempts,
            "refinement_saved": {"subtasks": list(subtasks)} if subtasks else None, "refinements_used": [],
            "ticks": 100, "objects": {"bar": {"pose": [x, 0.0, 0.1, 0.0, 0.0, 0.0]},
                                      "block": {"pose": [0.2, 0.1, 0.1, 0.0, 0.0, 0.0]}}}


@pytest.mark.parametrize(("ros", "why"), [
    (_report(x=0.5009), ""),
    (_report(x=0.5011), "object poses differ by 1.100 mm (bar)"),
    (_report(status="FAILURE"), "status: SUCCESS / FAILURE"),
    (_report(kinds=("unknown_entity", "verification")), "failure_kinds: ['unknown_entity'] / ['unknown_entity', "
                                                        "'verification']"),
    (_report(attempts=2), "attempts: 1 / 2"),
    (_report(subtasks=("MoveTo(b)",)), "learned refinements differ"),
    ({"error": "exit 2: no server"}, "ROS 2 run failed: exit 2: no server"),
])
def test_compare_names_what_differs(ros, why):
    from bt_meta.experiments.ros2_compare import compare

    row = compare(_report(), ros)
    assert row["alike"] is (why == "")
    assert why in row["why"]
    if why == "":
        assert row["pose_difference_object"] == "bar" and abs(row["pose_difference_mm"] - 0.9) < 1e-6
