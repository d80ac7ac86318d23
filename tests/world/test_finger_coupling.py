"""How a friction gripper's two fingers close and hold (the Panda's): coupled, they close as mirror images and the
part ends in their middle; once holding, they stop where they closed on it; a part pushed along the pads while both
still squeeze it (pressed onto a support) has slid in the grasp, not dropped out of it. A hand-built scene: a part
on a pedestal between the fingers of the Panda at home."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest

from bt_meta.world.robot.description import load_robot
from bt_meta.world.simulation.objects import AttachmentFeature, Box, ObjectModel, megablok

BOTTOM = (AttachmentFeature("bottom", (0.0, 0.0, -0.01), (0.0, 0.0, -1.0)),)
PEDESTAL = ObjectModel(type="pedestal", colour="white", parts=(Box((0.02, 0.02, 0.02)),), mass=0.0,
                       features=BOTTOM, primary="bottom")


def _between_fingers(part: ObjectModel):
    """The Panda at home with ``part`` standing on a pedestal between its open fingers, its top 5 mm above the
    gripper frame (the pads on its body)."""
    from bt_meta.world.simulation.sim import Simulation

    sim = Simulation(robot=load_robot("panda"))
    tcp = sim.link_transform("panda_hand_tcp")[:3, 3]
    low, high = part.extent()
    centre = tcp[2] + 0.005 - float(high[2])
    sim.spawn("part", part, [tcp[0], tcp[1], centre, 0.0, 0.0, 0.0])
    sim.add_obstacle("pedestal", PEDESTAL, [tcp[0], tcp[1], centre + float(low[2]) - 0.0105, 0.0, 0.0, 0.0])
    sim.settle(60)
    return sim


def _fingers(sim) -> np.ndarray:
    return np.array([pybullet.getJointState(sim.robot_id, sim.joint_index(j), physicsClientId=sim.client)[0]
                     for j in ("panda_finger_joint1", "panda_finger_joint2")])


def _off_middle(sim) -> float:
    """How far (m) the part's centre lies from the fingers' middle, along the closing axis."""
    tcp = sim.link_transform("panda_hand_tcp")
    return float((sim.object_transform("part")[:3, 3] - tcp[:3, 3]) @ sim.closing_axis("arm"))


@pytest.mark.slow
def test_coupled_fingers_close_as_mirror_images_and_centre_the_part():
    sim = _between_fingers(megablok("1x1", "blue"))
    try:
        assert sim.grasp("part", "arm")
        sim.step(240)  # a second of holding it
        left, right = _fingers(sim)
        # loosely coupled (the gear's 0.1) the pair crept sideways: 5-6 mm apart, the block 1.5 mm off the middle
        assert abs(left - right) < 0.001, (left, right)
        assert abs(_off_middle(sim)) < 0.0005
        assert sim.held("arm") == "part" and sim.touching_fingers("part", "arm") == 2
    finally:
        sim.close()


def _lower_hand(sim, by: float) -> None:
    """Drive the arm so the gripper frame goes ``by`` metres straight down (pybullet's IK; slowly)."""
    link = sim.link_index("panda_hand_tcp")
    target = sim.link_transform("panda_hand_tcp")[:3, 3] - np.array([0.0, 0.0, by])
    turn = pybullet.getLinkState(sim.robot_id, link, physicsClientId=sim.client)[5]
    solution = pybullet.calculateInverseKinematics(sim.robot_id, link, list(target), turn, physicsClientId=sim.client)
    joints = [pybullet.getJointInfo(sim.robot_id, i, physicsClientId=sim.client)
              for i in range(pybullet.getNumJoints(sim.robot_id, physicsClientId=sim.client))]
    movable = [info[1].decode() for info in joints if info[2] != pybullet.JOINT_FIXED]
    q = dict(zip(movable, solution, strict=True))
    sim.set_joint_targets({j: q[j] for j in sim.robot.arm("arm").joints}, max_velocity=0.05)


@pytest.mark.slow
def test_a_part_pressed_onto_a_support_slides_in_the_fingers_and_stays_held():
    sim = _between_fingers(megablok("1x1", "blue"))
    try:
        assert sim.grasp("part", "arm")
        start, hand_start = sim.object_transform("part")[:3, 3], sim.link_transform("panda_hand_tcp")[:3, 3]
        _lower_hand(sim, 0.015)  # the part stands on the pedestal: the hand goes 1.5 cm further down around it
        sim.step(240)
        hand = sim.link_transform("panda_hand_tcp")[:3, 3]
        part = sim.object_transform("part")[:3, 3]
        assert hand[2] < hand_start[2] - 0.01  # the hand went down...
        assert abs(part[2] - start[2]) < 0.002  # ...the part did not: it slid up in the fingers
        # before: "lost" once it had slid 5 mm, though both fingers still squeezed it (and the loose pair then
        # carried it 1.7 cm sideways)
        assert sim.held("arm") == "part" and sim.touching_fingers("part", "arm") == 2
        assert np.linalg.norm(part[:2] - start[:2]) < 0.002
    finally:
        sim.close()
