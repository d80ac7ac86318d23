"""Self-collision with the SRDF's pairs removed, and a run-time scene of named objects."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from bt_meta.errors import KinematicsError
from bt_meta.world.kinematics.collision import as_se3, pose_from_xyz_rpy

# Right shoulder swung in and raised, elbow bent: the elbow goes into the head's collision sphere.
ELBOW_IN_HEAD = {"right_s0": 1.0, "right_s1": -1.5, "right_e0": 0.0, "right_e1": 1.5, "right_w0": 0.0, "right_w1": 0.0}


@pytest.fixture
def scene(checker):
    """The module's checker, emptied after each test so scene objects never leak between tests."""
    yield checker
    checker.clear_scene()


def test_no_self_collision_at_home_and_reference(checker, kin):
    assert checker.check(kin.home) is None
    assert checker.check(kin.reference) is None
    assert checker.all_contacts(kin.home) == []


def test_srdf_pairs_are_removed(checker):
    pairs = {
        frozenset((checker._name_of(first), checker._name_of(second))) for first, second in checker.checked_pairs
    }
    assert frozenset(("collision_head_link_1", "collision_head_link_2")) not in pairs  # SRDF: adjacent
    assert frozenset(("collision_head_link_1", "right_lower_elbow")) in pairs
    assert checker.n_self_pairs == 547
    assert checker.n_scene_pairs == 0


def test_known_colliding_configuration(checker, kin):
    q = kin.q_from_dict(ELBOW_IN_HEAD, kin.home)
    contact = checker.check(q)
    assert contact is not None
    assert contact.pair == ("collision_head_link_1", "right_lower_elbow")
    assert contact.kind == "self"
    assert contact.penetration == pytest.approx(0.0326, abs=1e-3)
    assert str(contact) == "collision_head_link_1 <-> right_lower_elbow (penetration 32.6 mm)"
    assert contact in checker.all_contacts(q)
    assert checker.check(q, self_collision=False) is None  # no scene: nothing else to hit


def test_broad_phase_agrees_with_the_ordered_pass(checker, kin):
    rng = np.random.default_rng(12)
    colliding = 0
    for _ in range(200):
        q = kin.random_q(rng, "right")
        first = checker.check(q)
        every = checker.all_contacts(q)
        assert (first is None) == (not every)
        if first is not None:
            colliding += 1
            assert first.pair == every[0].pair
    assert 30 < colliding < 120  # about a third of random right-arm configurations self-collide


def test_box_at_the_gripper_is_reported_by_name(scene, kin):
    gripper = kin.end_effector_pose(kin.home, "right")
    scene.add_box("block", (0.05, 0.05, 0.05), gripper)
    contact = scene.check(kin.home)
    assert contact is not None and contact.second == "block" and contact.kind == "scene"
    assert contact.first.startswith("r_gripper") or contact.first.startswith("right_")
    assert scene.check(kin.home, scene=False) is None
    assert scene.objects["block"].shape == "box" and scene.objects["block"].dimensions == (0.05, 0.05, 0.05)


def test_moving_and_removing_objects(scene, kin):
    gripper = kin.end_effector_pose(kin.home, "right")
    scene.add_cylinder("shaft", 0.01, 0.1, (2.0, 0.0, 0.0))
    assert scene.check(kin.home) is None
    scene.move("shaft", gripper)
    assert scene.check(kin.home).second == "shaft"
    assert scene.pose("shaft").isApprox(gripper)
    scene.move("shaft", (2.0, 0.0, 0.0, 0.0, 0.0, 0.3))
    assert scene.check(kin.home) is None
    scene.move("shaft", gripper.homogeneous)
    assert scene.check(kin.home) is not None
    scene.remove("shaft")
    assert scene.check(kin.home) is None
    assert "shaft" not in scene.objects
    with pytest.raises(KinematicsError, match="unknown scene object 'shaft'; scene objects: none"):
        scene.move("shaft", gripper)


def test_table_distance_and_errors(scene, kin):
    scene.add_box("table", (0.8, 1.4, 0.1), (0.8, 0.0, -0.2))
    assert scene.check(kin.home) is None
    distance, link = scene.distance(kin.home, "table")
    assert 0.0 < distance < 0.5 and link
    scene.add_sphere("ball", 0.02, (0.8, 0.0, -0.13))  # resting on the table: fixed objects are not paired
    assert scene.check(kin.home) is None
    with pytest.raises(KinematicsError, match="already exists"):
        scene.add_box("table", (1, 1, 1), (0, 0, 0))
    with pytest.raises(KinematicsError, match="box size must be 3 positive numbers"):
        scene.add_box("slab", (1, 0, 1), (0, 0, 0))
    with pytest.raises(KinematicsError, match="a pose is an SE3"):
        scene.add_box("slab", (1, 1, 1), (0, 0))
    with pytest.raises(KinematicsError, match="unknown collision link or scene object 'thumb'"):
        scene.allow("table", ["thumb"])


def test_allowed_pairs(scene, kin):
    gripper = kin.end_effector_pose(kin.home, "right")
    scene.add_box("held", (0.03, 0.03, 0.03), gripper * pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.03])))
    contacts = {c.first for c in scene.all_contacts(kin.home)}
    assert contacts and all(c.startswith("r_gripper") for c in contacts)
    scene.allow("held", contacts)
    assert scene.check(kin.home) is None
    scene.disallow("held")
    assert scene.check(kin.home) is not None


def test_attached_object_moves_with_the_arm(scene, kin):
    gripper = kin.end_effector_pose(kin.home, "right")
    scene.add_box("table", (1.0, 1.4, 0.1), (0.7, 0.0, -0.1))  # top at z = -0.05
    scene.add_box("held", (0.04, 0.04, 0.04), gripper * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1])))
    fingers = {c.first for c in scene.all_contacts(kin.home)}
    scene.attach("held", "right_gripper", kin.home, allow=fingers)
    assert scene.objects["held"].attached_to == "right_gripper"
    assert scene.check(kin.home) is None
    lowered = kin.q_from_dict({"right_s1": -0.3}, kin.home)
    expected = kin.end_effector_pose(lowered, "right") * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1]))
    assert scene.pose("held", lowered).isApprox(expected, 1e-9)
    assert expected.translation[2] < -0.05  # the carried box is pushed into the table, the hand is not
    contact = scene.check(lowered)
    assert contact is not None and contact.pair == ("table", "held")
    assert scene.check(kin.q_from_dict({"right_s1": -0.3}, kin.home), scene=False) is None
    scene.detach("held", q=lowered)
    assert scene.objects["held"].attached_to is None
    assert scene.pose("held").isApprox(expected, 1e-9)
    with pytest.raises(KinematicsError, match="needs the pose"):
        scene.detach("held")


def test_a_carried_object_keeps_a_clearance_from_other_objects_when_asked_not_from_the_table(scene, kin):
    from bt_meta.world.kinematics.collision import TABLE

    gripper = kin.end_effector_pose(kin.home, "right")
    held_at = gripper * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1]))
    scene.add_box("held", (0.04, 0.04, 0.04), held_at)
    fingers = {c.first for c in scene.all_contacts(kin.home)}
    scene.attach("held", "right_gripper", kin.home, allow=fingers)
    # another block 3 mm beside the carried one, the table top 3 mm under it
    beside = held_at * pin.SE3(np.eye(3), np.array([0.043, 0.0, 0.0]))
    scene.add_box("beside", (0.04, 0.04, 0.04), beside)
    scene.add_box(TABLE, (0.1, 0.1, 0.01), held_at.translation - np.array([0.0, 0.0, 0.02 + 0.003 + 0.005]))
    assert scene.check(kin.home) is None
    contact = scene.check(kin.home, carried_clearance=0.005)
    assert contact is not None and set(contact.pair) == {"held", "beside"}
    assert scene.check(kin.home, carried_clearance=0.002) is None
    scene.remove("beside")
    assert scene.check(kin.home, carried_clearance=0.005) is None  # the table: no clearance kept
    assert scene.check(kin.home) is None  # the margin does not stay on the pairs


def test_pose_helpers():
    pose = pose_from_xyz_rpy(1, 2, 3, 0.1, 0.2, 0.3)
    assert np.allclose(pin.rpy.matrixToRpy(pose.rotation), [0.1, 0.2, 0.3])
    assert as_se3(pose.homogeneous).isApprox(pose)
    assert as_se3((1, 2, 3)).translation.tolist() == [1, 2, 3]


def test_a_carried_object_may_press_a_little_into_a_movable_object_not_into_a_fixed_one(scene, kin):
    """A negative clearance (the place skill's set-down beside nudged neighbours): 2 mm into another block is not a
    collision within 3 mm; into the table or a fixed obstacle it still is."""
    from bt_meta.world.kinematics.collision import TABLE

    gripper = kin.end_effector_pose(kin.home, "right")
    held_at = gripper * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1]))
    scene.add_box("held", (0.04, 0.04, 0.04), held_at)
    fingers = {c.first for c in scene.all_contacts(kin.home)}
    scene.attach("held", "right_gripper", kin.home, allow=fingers)
    scene.add_box("nudged", (0.04, 0.04, 0.04), held_at * pin.SE3(np.eye(3), np.array([0.038, 0.0, 0.0])))
    contact = scene.check(kin.home)
    assert contact is not None and set(contact.pair) == {"held", "nudged"}
    assert scene.check(kin.home, carried_clearance=-0.003) is None
    assert scene.check(kin.home, carried_clearance=-0.001) is not None  # deeper than allowed
    scene.fix("nudged")  # a static obstacle is not pushed back
    assert scene.check(kin.home, carried_clearance=-0.003) is not None
    scene.remove("nudged")
    scene.add_box(TABLE, (0.1, 0.1, 0.01), held_at.translation - np.array([0.0, 0.0, 0.02 + 0.005 - 0.002]))
    assert scene.check(kin.home, carried_clearance=-0.003) is not None  # 2 mm into the table
