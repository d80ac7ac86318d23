"""The Franka Panda as data (robots/panda.yaml), a third robot from a YAML file alone, and the paper's tasks run
on the Panda from the command line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from bt_meta.cli import main
from bt_meta.errors import ConfigError
from bt_meta.resources import robots_dir, trees_dir
from bt_meta.world.robot.description import load_robot

PANDA_TEXT = (robots_dir() / "panda.yaml").read_text(encoding="utf-8")


def test_panda_description_names_its_arm_hand_and_camera_frames():
    panda = load_robot("panda")
    assert panda.name == "panda" and panda.base_frame == "panda_link0"
    assert panda.default_arm == "arm"
    arm = panda.arm("arm")
    assert arm.joints == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert arm.end_effector == "panda_hand_tcp" and arm.camera == "panda_hand"
    assert arm.top_down_yaw == 0.0 and load_robot("baxter").arm("right").top_down_yaw == pytest.approx(math.pi)
    assert arm.gripper is not None and arm.gripper.opening == pytest.approx(0.08)
    assert arm.gripper.opening > 0.061  # wider than a Mega Blok, unlike the Baxter's
    assert panda.home["panda_joint4"] == pytest.approx(-2.35619)
    assert panda.scene_offset == (-0.22, 0.20, 0.20)
    assert load_robot("baxter").scene_offset == (0.0, 0.0, 0.0)


def test_panda_home_points_the_hand_down_in_front_of_the_base():
    from bt_meta.world.kinematics.forward import Kinematics

    kin = Kinematics(load_robot("panda"))
    pose = kin.frame_pose(kin.home, "panda_hand_tcp")
    assert pose.translation == pytest.approx([0.307, 0.0, 0.487], abs=2e-3)
    assert pose.rotation[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-3)  # approach axis down


def test_scene_offset_errors_are_located(tmp_path: Path):
    path = tmp_path / "panda2.yaml"
    path.write_text(PANDA_TEXT.replace("scene_offset: [-0.22, 0.20, 0.20]", "scene_offset: [-0.22, 0.20]"))
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if "scene_offset" in text)
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert str(info.value) == f"{path}:{line}:17: workcell.scene_offset must be [x, y, z] (metres)"
    path.write_text(PANDA_TEXT.replace("scene_offset:", "offset:"))
    with pytest.raises(ConfigError, match=r"panda2.yaml:\d+:\d+: .*offset"):
        load_robot(path)


def test_unknown_robot_on_the_command_line_is_exit_2(capsys):
    code = main(["run", str(trees_dir() / "letters.yaml"), "--problem", "A", "--robot", "nosuch"])
    err = capsys.readouterr().err
    assert code == 2
    assert "no robot description 'nosuch'; available: baxter, panda, ur5" in err and "Traceback" not in err


def test_a_urdf_that_does_not_load_is_a_located_error(tmp_path: Path):
    share = tmp_path / "share"
    share.mkdir()
    (share / "broken.urdf").write_text('<robot name="broken">\n  <link name="a">\n</robot>\n')
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nfiles: {share: share, urdf: broken.urdf}\nbase_frame: a\narms: {}\n")
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert str(info.value).startswith(f"{share / 'broken.urdf'}:3:3: URDF is not well-formed XML")


UR5_YAML = """\
# A robot bt-meta does not ship: the UR5 from example-robot-data, described by this file alone.
name: ur5
files:
  distribution: example-robot-data
  share: cmeel.prefix/share
  urdf: example-robot-data/robots/ur_description/urdf/ur5_robot.urdf
  srdf: example-robot-data/robots/ur_description/srdf/ur5.srdf
base_frame: base_link
arms:
  main:
    joints: [shoulder_pan_joint, shoulder_lift_joint, elbow_joint, wrist_1_joint, wrist_2_joint, wrist_3_joint]
    end_effector: tool0
home: {shoulder_lift_joint: -1.57, elbow_joint: 1.57, wrist_1_joint: -1.57, wrist_2_joint: -1.57}
workcell: {scene_offset: [-0.25, 0.25, 0.2]}
ik: {max_attempts: 30, seed: 3}
"""


@pytest.mark.slow
def test_a_third_robot_needs_only_a_yaml_file(tmp_path: Path):
    from bt_meta.world.kinematics.collision import CollisionChecker
    from bt_meta.world.kinematics.forward import Kinematics
    from bt_meta.world.kinematics.ik import InverseKinematics
    from bt_meta.world.simulation.sim import Simulation

    path = tmp_path / "ur5.yaml"
    path.write_text(UR5_YAML)
    ur5 = load_robot(path)
    assert ur5.default_arm == "main" and ur5.ik.max_attempts == 30
    kin = Kinematics(ur5)
    ik = InverseKinematics(kin, CollisionChecker(kin))
    down = pin.SE3(np.diag([1.0, -1.0, -1.0]), np.array([0.35, 0.15, 0.25]))
    result = ik.solve("main", down, kin.home, seed=1)
    assert result.success, result.message
    reached = kin.frame_pose(result.q, "tool0")
    assert np.linalg.norm(reached.translation - down.translation) < 1e-3
    with Simulation(robot=ur5) as sim:
        assert sim.table.top_z == pytest.approx(0.0) and sim.table.center_x == pytest.approx(0.5)
        sim.set_joint_positions(kin.q_to_dict(result.q))
        assert sim.link_transform("tool0")[:3, 3] == pytest.approx(down.translation, abs=1e-3)
    far = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.3]))
    unreachable = ik.solve("main", far, kin.home)
    assert not unreachable.success and unreachable.kind == "reachability"


def run_json(capsys, *args: str) -> tuple[int, dict]:
    code = main(["run", *args, "--json"])
    out = capsys.readouterr().out
    return code, json.loads(out)


@pytest.mark.slow
def test_letter_a_on_the_panda(capsys):
    code, result = run_json(capsys, str(trees_dir() / "letters.yaml"), "--problem", "A", "--robot", "panda")
    assert code == 0 and result["status"] == "SUCCESS" and result["robot"] == "panda"
    for line in result["plan"]:
        _, block, x, y = line.split()
        assert ["at", block, x, y] in result["symbolic_state"]
        assert result["objects"][block]["held_by"] is None
        assert result["objects"][block]["pose"][2] < 0.05  # on the Panda's table (top at z = 0), not in the hand


@pytest.mark.slow
def test_magnetic_attach_nominal_on_the_panda(capsys):
    code, result = run_json(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal",
                            "--robot", "panda")
    assert code == 0 and result["status"] == "SUCCESS"
    assert result["attachments"] == [["active", "reference"]]  # the magnets met in the simulator
    assert result["objects"]["reference"]["pose"][2] > 0.1  # the subassembly went to the staging pose


@pytest.mark.slow
def test_letter_h_on_the_panda(capsys):
    """The lift next to a wrist joint limit and the fingers beside placed blocks: IK keeps off the limits
    (joint_limit_margin), Place turns the fingers to a free side."""
    code, result = run_json(capsys, str(trees_dir() / "letters.yaml"), "--problem", "H", "--robot", "panda")
    assert code == 0 and result["status"] == "SUCCESS", result["failures"]
    assert len(result["plan"]) == 8
    for line in result["plan"]:
        _, block, x, y = line.split()
        assert ["at", block, x, y] in result["symbolic_state"]
        assert result["objects"][block]["held_by"] is None and result["objects"][block]["pose"][2] < 0.05


@pytest.mark.slow
def test_housing_insertion_nominal_on_the_panda(capsys):
    """The pose symbols point the hand down with the Panda's own top-down yaw (0, not the Baxter's 180)."""
    code, result = run_json(capsys, str(trees_dir() / "housing_insertion.yaml"), "--problem", "nominal",
                            "--robot", "panda")
    assert code == 0 and result["status"] == "SUCCESS", result["failures"]
    housing, board = result["objects"]["housing"], result["objects"]["board"]
    assert housing["held_by"] is None
    assert housing["an"][2] == pytest.approx(-1.0, abs=0.02)  # upright: its insertable end faces down
    assert np.linalg.norm(np.array(housing["pose"][:2]) - np.array(board["pose"][:2])) < 0.01  # in the board


@pytest.mark.slow
def test_a_robot_placed_too_far_from_the_objects_reports_reachability(tmp_path, capsys):
    far = tmp_path / "far_panda.yaml"
    far.write_text(PANDA_TEXT.replace("scene_offset: [-0.22, 0.20, 0.20]", "scene_offset: [0.45, 0.20, 0.20]"))
    code, result = run_json(capsys, str(trees_dir() / "letters.yaml"), "--problem", "A", "--robot", str(far))
    assert code == 1 and result["status"] == "FAILURE"
    (failure,) = result["failures"]
    assert failure["kind"] == "reachability" and failure["args"] == ["b0", "0", "0"]
    assert failure["evidence"]["target_xyz"][0] == pytest.approx(0.55 + 0.45, abs=0.01)  # the block, moved away
    assert failure["evidence"]["label"] == "above b0"


def test_bench_ik_on_the_panda_against_pybullet_in_the_same_run():
    from bt_meta.bench.ik import run_benchmark

    report = run_benchmark(n=6, seed=2, arm=None, pybullet_calls=3, robot_name="panda")
    assert report["robot"] == "panda" and report["arm"] == "arm"  # the robot's first arm
    assert report["ours"]["successes"] >= 5 and report["ours"]["every_returned_solution_collision_free"]
    assert report["pybullet"]["mean_ms"] is not None and report["ratio_mean_time_pybullet_over_ours"] is not None
