"""Faults with real rclpy processes (each tree in a loopback-only network namespace): no server, a goal rejected or
aborted, the robot process killed mid-run, Ctrl-C."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from bt_meta.memory.store import EpisodicMemory

BT_META = [sys.executable, "-m", "bt_meta.cli"]

LETTERS = "trees/letters.yaml"
START = ("--joint", "left_s0=0.8")
RUN = ("run", LETTERS, "--problem", "A", "--world", "ros2")


def _config(tmp_path, server: float = 15.0, result: float = 3.0):
    path = tmp_path / "ros2.yaml"
    path.write_text(f"timeouts: {{server: {server}, result: {result}}}\n")
    return str(path)


def _wait_for(served, run, text: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while text not in served.log.read_text():
        if run.poll() is not None or time.monotonic() > deadline:
            run.kill()
            raise AssertionError(f"no {text!r} in the server's log; the run: {run.communicate()[1][-2000:]}")
        time.sleep(0.1)


@pytest.mark.slow
def test_no_server_is_an_error_naming_the_action_and_the_timeout_before_any_motion(loopback_only, tmp_path):
    started = time.monotonic()
    done = loopback_only(*BT_META, *RUN, "--ros2", _config(tmp_path, server=2.0))
    assert done.returncode == 2, done.stderr
    assert "no action server /right_arm_controller/follow_joint_trajectory within the 2 s server timeout" in done.stderr
    assert "nothing was moved" in done.stderr and time.monotonic() - started < 60


@pytest.mark.slow
@pytest.mark.parametrize(("fault", "code"), [("reject@3", None), ("abort@3:-5", -5)])
def test_a_rejected_or_aborted_goal_is_a_classified_failure_with_the_error_code(serve, fault, code):
    served = serve("--scene", "letters_A", *START, "--fault", fault)
    done = served.run(*RUN, "--json")
    assert done.returncode == 1, done.stderr[-2000:]
    result = json.loads(done.stdout)
    assert result["status"] == "FAILURE"
    failure = result["failures"][0]
    assert failure["kind"] == "physical" and failure["step"] == 0
    assert "/right_arm_controller/follow_joint_trajectory" in failure["message"]
    evidence = failure["evidence"]
    assert evidence["error_code"] == code and evidence["rejected"] is (code is None)


@pytest.mark.slow
def test_the_robot_killed_mid_run_stops_the_run_within_the_bound_and_stores_no_trace(serve, tmp_path):
    memory = tmp_path / "memory.sqlite"
    served = serve("--scene", "letters_A", *START)
    run = served.start(*RUN, "--ros2", _config(tmp_path, result=3.0), "--memory", str(memory), "--record", "--json")
    _wait_for(served, run, "first goal")
    served.process.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    out, err = run.communicate(timeout=120)
    assert time.monotonic() - killed < 60
    assert run.returncode == 1, err[-2000:]
    # the run ends with one line saying where it stopped, not a report of a world it can no longer observe
    # named after the action that went unanswered: the arm's trajectory or the gripper's command, whichever had a
    # goal in flight when the robot died
    assert "bt-meta: lost the robot" in err
    assert any(action in err for action in ("/right_arm_controller/follow_joint_trajectory",
                                            "/right_gripper_controller/gripper_cmd")), err[-2000:]
    assert "within 3 s (after " in err and out == ""
    with EpisodicMemory.open(memory, readonly=True) as opened:
        assert opened.episodes() == []


@pytest.mark.slow
def test_ctrl_c_cancels_and_exits_130(serve, tmp_path):
    served = serve("--scene", "letters_A", *START)
    run = served.start(*RUN, "--ros2", _config(tmp_path))
    _wait_for(served, run, "first goal")
    time.sleep(0.5)
    run.send_signal(signal.SIGINT)
    try:
        _out, err = run.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        run.kill()
        raise
    assert run.returncode == 130, err[-2000:]
    assert "interrupted" in err
    assert served.process.poll() is None  # the served robot is unharmed and still serving


@pytest.mark.slow
def test_feedback_that_never_arrives_is_named_as_a_definitions_mismatch(serve):
    served = serve("--scene", "letters_A", *START, "--fault", "no-feedback")
    done = served.run(*RUN, "--json")
    assert done.returncode == 0, done.stderr[-2000:]  # goals and results still work: only feedback is lost
    assert json.loads(done.stdout)["status"] == "SUCCESS"
    warning = [line for line in done.stderr.splitlines() if line.startswith("bt-meta: warning:")]
    assert len(warning) == 1, done.stderr[-2000:]
    assert "/right_arm_controller/follow_joint_trajectory: 10 goals succeeded without any feedback" in warning[0]
    assert "control_msgs definitions of another ROS 2 distro" in warning[0]


def test_a_bad_fault_spec_exits_2(capsys):
    from bt_meta.cli import main

    assert main(["sim", "serve", "--ros2", "--scene", "letters_A", "--fault", "no-results"]) == 2
    assert "expected reject@N, abort@N[:CODE] or no-feedback" in capsys.readouterr().err
