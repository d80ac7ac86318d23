"""Every output that prints a pose says its frame: ``run --json`` names the robot base frame its poses are in and
how the scene frame relates to it, ``run`` prints both, IK failures name the base frame of their target."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main
from bt_meta.resources import trees_dir
from bt_meta.world.robot.description import load_robot


@pytest.mark.parametrize("robot", ["baxter", "panda", "ur5"])
def test_the_scene_and_base_frames_differ_by_the_robot_files_offset(robot):
    description = load_robot(robot)
    frames = description.frames()
    assert frames["poses"] == "base" and frames["base_frame"] == description.base_frame
    assert frames["scene_offset"] == list(description.scene_offset)
    point = (0.62, -0.10, -0.16)
    base = description.scene_to_base(point)
    assert base == pytest.approx([p + d for p, d in zip(point, description.scene_offset, strict=True)])
    assert description.base_to_scene(base) == pytest.approx(point)


@pytest.mark.slow
def test_run_names_the_frame_of_its_poses(capsys):
    task = str(trees_dir() / "magnetic_attach.yaml")
    assert main(["run", task, "--problem", "nominal", "--robot", "ur5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    ur5 = load_robot("ur5")
    assert result["frames"] == {"poses": "base", "base_frame": "base_link", "scene_offset": list(ur5.scene_offset),
                                "scene_to_base": "base = scene + scene_offset (no rotation)"}
    reference = result["objects"]["reference"]["pose"]
    assert main(["run", task, "--problem", "nominal", "--robot", "ur5"]) == 0
    text = capsys.readouterr().out
    assert "object positions: base frame (base_link); scene frame = base - [-0.12, 0.2, 0.2]" in text
    scene = ur5.base_to_scene(reference[:3])
    line = next(line for line in text.splitlines() if line.strip().startswith("reference"))
    assert f"({reference[0]:.3f}, {reference[1]:.3f}, {reference[2]:.3f}) base" in line
    assert f"({scene[0]:.3f}, {scene[1]:.3f}, {scene[2]:.3f}) scene" in line


def test_an_ik_failure_names_the_base_frame_of_its_target():
    import numpy as np
    import pinocchio as pin

    from bt_meta.world.kinematics.collision import CollisionChecker
    from bt_meta.world.kinematics.forward import Kinematics
    from bt_meta.world.kinematics.ik import InverseKinematics

    kin = Kinematics(load_robot("ur5"))
    result = InverseKinematics(kin, CollisionChecker(kin)).solve("arm", pin.SE3(np.eye(3), np.array([2.0, 0, 0.3])))
    assert not result.success and result.evidence["target_frame"] == "base_link"
    assert "at [2.0, 0.0, 0.3] (base frame base_link)" in result.message
