"""A gripper described ``turn_about_fingers`` (the Panda's hand, 20 cm long across its fingers) re-orients a part
about the fingers' axis, so the hand stays level: turned the other way it reached into the table at the
set-down spot (every IK solution of ``turn_low`` collided, panda_hand / table). Real robot model, headless sim."""

from __future__ import annotations

import numpy as np
import pytest

from bt_meta.resources import trees_dir

MAGNETIC = trees_dir() / "magnetic_attach.yaml"


def _world(robot, variant):
    from bt_meta.world.simulation.sim_world import SimWorld

    return SimWorld.from_task_file(MAGNETIC, "nominal", variant=variant, robot=robot)


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["active_on_side", "active_on_side_turned"])
def test_a_part_on_its_side_is_grasped_across_the_axis_it_turns_about(variant):
    world = _world("panda", variant)
    try:
        arm = world.default_arm
        part = world.sim.object_transform("active")
        axis = np.cross(part[:3, 2], [0.0, 0.0, 1.0])
        axis /= np.linalg.norm(axis)
        fingers = world.fingers_axis(world.ground_pose("active_grasp")[:3, :3], arm)
        assert abs(float(fingers @ axis)) == pytest.approx(1.0, abs=1e-6)
        for symbol in ("turn_high", "turn_low"):  # not held yet: the turn a grasp there would make
            assert abs(float(world.fingers_axis(world.ground_pose(symbol)[:3, :3], arm)[2])) < 1e-6  # level
    finally:
        world.close()


@pytest.mark.slow
def test_an_upside_down_part_is_flipped_about_the_fingers():
    world = _world("panda", "active_upside_down")
    try:
        arm = world.default_arm
        turned = world.ground_pose("turn_high")[:3, :3]
        assert abs(float(world.fingers_axis(turned, arm)[2])) < 1e-6  # the hand's long side stays level
        assert float(turned[2, 2]) == pytest.approx(0.0, abs=1e-6)  # a quarter turn: pointing sideways
    finally:
        world.close()


@pytest.mark.slow
def test_a_gripper_without_the_flag_grasps_a_part_on_its_side_unturned():
    world = _world("baxter", "active_on_side")
    try:
        assert world.own_heading("active", world.default_arm) == 0.0
    finally:
        world.close()
