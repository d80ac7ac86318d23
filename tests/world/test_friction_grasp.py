"""Grasp by finger contact and friction (a robot description's ``gripper: grasp: friction``, the Panda's): a part
that fits the fingers is held only while both fingers touch it and by no more than their friction, so a part too
heavy or too slippery for them slips out in the simulator and the skill reports ``physical``; ``grasp: fixed`` (the
Baxter's, and an option for the Panda) holds the same part by constraint."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from bt_meta.errors import ConfigError
from bt_meta.resources import robots_dir, trees_dir
from bt_meta.world.base import FAILURE, RUNNING, SUCCESS
from bt_meta.world.robot.description import load_robot

PANDA_TEXT = (robots_dir() / "panda.yaml").read_text(encoding="utf-8")

BRICKS = """\
types:
  brick:
    description: A 6.1 cm brick as heavy as the letter's blocks
    shape: box
    size: [0.061, 0.061, 0.0366]
    mass: 0.02
    colour: blue
    features:
      bottom: {point: [0.0, 0.0, -0.0183], normal: [0.0, 0.0, -1.0]}
    grasp_frames:
      top: [0.0, 0.0, 0.0223, 180, 0, 180]
  heavy_slippery_brick:
    description: The same brick in steel with an oiled surface (2 kg, friction 0.05)
    shape: box
    size: [0.061, 0.061, 0.0366]
    mass: 2.0
    colour: red
    friction: 0.05
    features:
      bottom: {point: [0.0, 0.0, -0.0183], normal: [0.0, 0.0, -1.0]}
    grasp_frames:
      top: [0.0, 0.0, 0.0223, 180, 0, 180]
"""


def _fixed_panda(tmp_path: Path) -> Path:
    assert "      grasp: friction\n" in PANDA_TEXT
    path = tmp_path / "panda_fixed.yaml"
    path.write_text(PANDA_TEXT.replace("      grasp: friction\n", "      grasp: fixed\n"))
    return path


def test_the_grasp_kind_is_per_robot_data(tmp_path: Path):
    panda, baxter = load_robot("panda").arm("arm").gripper, load_robot("baxter").arm("right").gripper
    assert panda is not None and baxter is not None
    assert panda.grasp == "friction" and panda.force > 0 and panda.depth > 0
    assert baxter.grasp == "fixed"  # its fingers open 4.62 cm, less than a block
    fixed = load_robot(_fixed_panda(tmp_path)).arm("arm").gripper
    assert fixed is not None and fixed.grasp == "fixed"


def test_an_unknown_grasp_kind_is_a_located_error(tmp_path: Path):
    path = tmp_path / "panda_glue.yaml"
    path.write_text(PANDA_TEXT.replace("      grasp: friction\n", "      grasp: glue\n"))
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if text.strip() == "grasp: glue")
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert str(info.value).startswith(f"{path}:{line}:14: arms.arm.gripper.grasp must be 'fixed' or 'friction'")


def test_the_joint_limit_margin_keeps_ik_off_the_panda_limits(tmp_path: Path):
    panda = load_robot("panda")
    assert panda.joint_limits["panda_joint6"][1] == pytest.approx(3.7525 - 0.1)
    assert panda.joint_limits["panda_finger_joint1"] == pytest.approx((0.0, 0.04))  # not an arm joint
    path = tmp_path / "panda_margin.yaml"
    path.write_text(PANDA_TEXT.replace("joint_limit_margin: 0.1", "joint_limit_margin: 3.0"))
    with pytest.raises(ConfigError, match=r"panda_margin.yaml:\d+:21: joint_limit_margin 3.0 must .* leave"):
        load_robot(path)


def _scene(tmp_path: Path, brick: str) -> Path:
    (tmp_path / "bricks.yaml").write_text(BRICKS)
    scene = (trees_dir() / "scenes" / "letters_A.yaml").read_text(encoding="utf-8")
    scene = scene.replace("scene: letters_A", "scene: bricks\ncatalogue: [bricks.yaml]")
    scene = scene.replace("{name: b0, type: megablok_1x1, colour: blue,", f"{{name: b0, type: {brick},")
    path = tmp_path / "bricks_scene.yaml"
    path.write_text(scene)
    return path


def _place(world, block: str) -> Any:
    skill = world.skill("place")
    skill.start([block, "0", "0"])
    for _ in range(400):
        status = skill.tick()
        if status != RUNNING:
            return skill
    raise AssertionError("place did not finish")


@pytest.mark.slow
@pytest.mark.parametrize(("grasp", "brick"), [("friction", "brick"), ("friction", "heavy_slippery_brick"),
                                              ("fixed", "heavy_slippery_brick")])
def test_a_heavy_slippery_part_slips_out_of_the_panda_fingers(tmp_path: Path, grasp: str, brick: str):
    from bt_meta.world.simulation.sim_world import SimWorld

    robot = "panda" if grasp == "friction" else _fixed_panda(tmp_path)
    world = SimWorld.from_task_file(trees_dir() / "letters.yaml", "A", robot=robot, scene=_scene(tmp_path, brick))
    try:
        assert world.sim.grasps_by_friction("b0", "arm") == (grasp == "friction")
        skill = _place(world, "b0").inner
        record = skill.record()
        phases = {p["phase"]: p for p in record["phases"]}
        assert phases["grasp"]["outcome"] == SUCCESS  # the fingers closed on it: both touched it
        if brick == "brick" or grasp == "fixed":  # a constraint holds even the heavy, slippery one
            assert skill.outcome == SUCCESS, record.get("failure")
            assert world.sim.held("arm") is None and world.sim.object_pose("b0")[2] < 0.05
        else:
            assert skill.outcome == FAILURE
            assert skill.failure.kind == "physical"
            assert "lost" in skill.failure.message
            assert world.sim.held("arm") is None  # slipped out, in the simulator
            assert world.sim.object_pose("b0")[2] < 0.05  # back down on the table, not in the hand
    finally:
        world.close()
