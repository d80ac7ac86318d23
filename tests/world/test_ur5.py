"""The UR5 with example-robot-data's claw (robots/ur5.yaml): a robot whose URDF lacks a tool centre point and whose
fingers do not move -- both data (``added_frames``, a gripper without joints and its ``closing_axis``) -- runs
every shipped task's nominal from the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bt_meta.cli import main
from bt_meta.errors import ConfigError
from bt_meta.resources import robots_dir, trees_dir
from bt_meta.world.robot.description import load_robot

UR5_TEXT = (robots_dir() / "ur5.yaml").read_text(encoding="utf-8")


def test_the_ur5_description_adds_its_tool_frames_to_the_urdf():
    from bt_meta.world.kinematics.forward import Kinematics

    ur5 = load_robot("ur5")
    arm = ur5.arm(ur5.default_arm)
    assert arm.end_effector == "tcp" and arm.camera == "wrist_camera"
    assert [f.name for f in ur5.added_frames] == ["tcp", "wrist_camera"]
    assert ur5.source_urdf_path is not None and ur5.source_urdf_path.name == "ur5_gripper.urdf"
    assert ur5.urdf_path != ur5.source_urdf_path and "tcp" in ur5.urdf_path.read_text(encoding="utf-8")
    assert arm.gripper is not None and arm.gripper.joints == () and arm.gripper.closing_axis == (1.0, 0.0, 0.0)
    assert arm.gripper.opening < 0.061 and arm.gripper.grasp == "fixed"  # narrower than a Mega Blok
    kin = Kinematics(ur5)
    tcp, tool0 = kin.frame_pose(kin.home, "tcp"), kin.frame_pose(kin.home, "tool0")
    assert tcp.rotation[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-4)  # home points the claw down
    assert tool0.translation - tcp.translation == pytest.approx([0.0, 0.0, 0.06], abs=1e-4)  # the fingertips
    yaw = np.degrees(np.arctan2(tcp.rotation[1, 0], tcp.rotation[0, 0]))
    assert yaw == pytest.approx(np.degrees(arm.top_down_yaw), abs=1e-3)  # top-down means as at home


def test_added_frame_and_fingerless_gripper_errors_are_located(tmp_path: Path):
    path = tmp_path / "ur5_bad.yaml"
    cases = [
        ("tcp: {parent: tool0,", "tcp: {parent: tool9,", r"added_frames\.tcp\.parent: unknown link 'tool9'"),
        ("tcp: {parent: tool0,", "tool0: {parent: tool0,", r"added_frames\.tool0: the URDF already has"),
        ("tcp: {parent: tool0, xyz: [0.0, 0.0, 0.06]}", "tcp: {parent: tool0, xyz: [0.0, 0.06]}",
         r"added_frames\.tcp\.xyz must be three numbers"),
        ("      closing_axis: [1, 0, 0]", "      closing_axis: [0, 0, 0]",
         r"arms\.arm\.gripper\.closing_axis must be three numbers"),
        ("      closing_axis: [1, 0, 0]", "      #", r"arms\.arm\.gripper: a gripper without finger joints needs"),
    ]
    for old, new, message in cases:
        assert old in UR5_TEXT
        path.write_text(UR5_TEXT.replace(old, new))
        with pytest.raises(ConfigError, match=rf"ur5_bad.yaml:\d+:\d+: {message}"):
            load_robot(path)


def run_json(capsys, *args: str) -> tuple[int, dict]:
    code = main(["run", *args, "--robot", "ur5", "--json"])
    return code, json.loads(capsys.readouterr().out)


@pytest.mark.slow
@pytest.mark.parametrize("problem", ["A", "H"])
def test_letters_on_the_ur5(capsys, problem: str):
    code, result = run_json(capsys, str(trees_dir() / "letters.yaml"), "--problem", problem)
    assert code == 0 and result["status"] == "SUCCESS" and result["robot"] == "ur5", result["failures"]
    for line in result["plan"]:
        _, block, x, y = line.split()
        assert ["at", block, x, y] in result["symbolic_state"]
        assert result["objects"][block]["held_by"] is None and result["objects"][block]["pose"][2] < 0.05


@pytest.mark.slow
def test_magnetic_attach_and_housing_insertion_nominal_on_the_ur5(capsys):
    code, result = run_json(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal")
    assert code == 0 and result["status"] == "SUCCESS", result["failures"]
    assert result["attachments"] == [["active", "reference"]]  # the magnets met in the simulator
    code, result = run_json(capsys, str(trees_dir() / "housing_insertion.yaml"), "--problem", "nominal")
    assert code == 0 and result["status"] == "SUCCESS", result["failures"]
    housing, board = result["objects"]["housing"], result["objects"]["board"]
    assert housing["held_by"] is None and housing["an"][2] == pytest.approx(-1.0, abs=0.02)  # upright, in
    assert np.linalg.norm(np.array(housing["pose"][:2]) - np.array(board["pose"][:2])) < 0.01


def test_bench_ik_on_the_ur5_against_pybullet_in_the_same_run():
    from bt_meta.bench.ik import run_benchmark

    report = run_benchmark(n=6, seed=2, arm=None, pybullet_calls=3, robot_name="ur5")
    assert report["robot"] == "ur5" and report["arm"] == "arm"
    assert report["ours"]["successes"] >= 5 and report["ours"]["every_returned_solution_collision_free"]
    assert report["pybullet"]["mean_ms"] is not None and report["ratio_mean_time_pybullet_over_ours"] is not None


@pytest.mark.slow
def test_the_ur5_wrist_camera_an_added_frame_sees_the_table():
    from bt_meta.world.simulation.camera import HandCamera
    from bt_meta.world.simulation.sim import Simulation

    with Simulation(robot=load_robot("ur5")) as sim:
        cam = HandCamera(sim, "arm")
        pose = cam.pose()
        assert np.allclose(pose, sim.link_transform("wrist_camera"))  # pybullet has the added frame too
        assert pose[2, 2] < -0.9  # at home it looks down
        image = cam.capture()
        centre = cam.pixel_to_point(160.0, 120.0, float(image.depth[120, 160]))
        assert sim.table.top_z - 0.01 < centre[2] < sim.table.top_z + 0.01  # the table, not the claw
