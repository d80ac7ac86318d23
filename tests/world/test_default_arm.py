"""No arm is named in code: the simulator, the skills and the hand camera default to the robot's first arm as its
YAML lists it (the Panda's and the UR5's is not the Baxter's "right"). Real robot models, headless simulator."""

from __future__ import annotations

import pytest

from bt_meta.resources import trees_dir


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "arm"), [("baxter", "right"), ("panda", "arm"), ("ur5", "arm")])
def test_calls_that_name_no_arm_use_the_robots_first_arm(robot, arm):
    from bt_meta.world.simulation.camera import HandCamera
    from bt_meta.world.simulation.sim_world import SimWorld
    from bt_meta.world.skills.grasp import Grasp
    from bt_meta.world.skills.move_to import MoveTo

    world = SimWorld.from_task_file(trees_dir() / "magnetic_attach.yaml", "nominal", robot=robot)
    try:
        sim = world.sim
        assert sim.robot.default_arm == arm
        assert sim.gripper_pose() == sim.gripper_pose(arm) and sim.held() is None and sim.release() is None
        assert Grasp(world).arm == arm and MoveTo(world).arm == arm
        assert HandCamera(sim).arm == arm
    finally:
        world.close()
