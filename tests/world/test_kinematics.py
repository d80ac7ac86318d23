"""Pinocchio forward kinematics and Jacobians, checked against MuJoCo and finite differences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from bt_meta.errors import KinematicsError
from bt_meta.world.kinematics.forward import Kinematics, pose_matrix, se3_from_matrix
from bt_meta.world.kinematics.mujoco_model import build_mujoco_model, mujoco_urdf_text
from bt_meta.world.robot.description import load_robot

FRAMES = ("right_gripper", "left_gripper", "right_hand_camera_link", "head_camera_link", "l_gripper_r_finger_tip")


def test_joint_order_and_arm_indices(kin):
    assert kin.nq == 19
    assert kin.joint_names[0] == "head_pan"
    assert kin.joint_names[1:8] == ("left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2")
    assert kin.joint_names[10:17] == (
        "right_s0",
        "right_s1",
        "right_e0",
        "right_e1",
        "right_w0",
        "right_w1",
        "right_w2",
    )
    assert list(kin.arm_indices("right")) == list(range(10, 17))
    assert kin.q_index("r_gripper_r_finger_joint") == 18
    with pytest.raises(KinematicsError, match="no arm 'center'"):
        kin.arm_indices("center")
    with pytest.raises(KinematicsError, match="unknown joint 'right_s7'"):
        kin.q_index("right_s7")


def test_home_and_named_configurations(kin):
    home = kin.q_to_dict(kin.home)
    assert home["right_e1"] == 1.94 and home["left_w2"] == -0.5 and home["head_pan"] == 0.0
    q = kin.q_from_dict({"right_s0": 0.3}, kin.home)
    assert q[kin.q_index("right_s0")] == 0.3 and q[kin.q_index("left_s0")] == -0.08
    assert kin.within_limits(kin.home)
    assert not kin.within_limits(kin.q_from_dict({"right_e1": 3.0}))
    assert kin.within_limits(kin.clamp(kin.q_from_dict({"right_e1": 3.0})))
    with pytest.raises(KinematicsError, match="a configuration has 19 values"):
        kin.check_q(np.zeros(7))


def test_home_pose_is_in_front_pointing_down(kin):
    pose = kin.end_effector_pose(kin.home, "right")
    assert pose.translation == pytest.approx([0.5797, -0.1833, 0.1137], abs=1e-3)
    assert pose.rotation[2, 2] < -0.99  # the gripper's z (approach) points down
    left = kin.end_effector_pose(kin.home, "left")
    assert left.translation[1] == pytest.approx(-pose.translation[1], abs=1e-9)  # mirrored arms


def test_srdf_reference_pose_strips_the_prefix(tmp_path, kin):
    robot = kin.robot
    srdf = tmp_path / "ref.srdf"
    srdf.write_text(
        '<robot name="baxter"><group_state name="neutral" group="whole_body">'
        '<joint name="baxter/right_e1" value="1.25"/><joint name="baxter/head_pan" value="-0.5"/>'
        "</group_state></robot>",
        encoding="utf-8",
    )
    text = (
        (robot.source)
        .read_text(encoding="utf-8")
        .replace("srdf: example-robot-data/robots/baxter_description/srdf/baxter_manipulation.srdf", f"srdf: {srdf}")
    )
    path = tmp_path / "robot.yaml"
    path.write_text(text, encoding="utf-8")
    other = Kinematics(load_robot(path))
    assert other.reference[other.q_index("right_e1")] == 1.25
    assert other.reference[other.q_index("head_pan")] == -0.5
    assert np.count_nonzero(other.reference) == 2
    assert np.count_nonzero(kin.reference) == 0  # Baxter's own "neutral" state is all zeros


def test_fk_pinocchio_and_mujoco_agree(kin):
    full = build_mujoco_model(kin)
    arm = build_mujoco_model(kin, "right")
    assert set(full.joint_names) == set(kin.joint_names) and full.joint_names != kin.joint_names  # mapped by name
    assert arm.joint_names == kin.robot.arms["right"].joints
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(50):
        q = kin.random_q(rng)
        poses = kin.frame_poses(q, FRAMES)
        for frame in FRAMES:
            position, rotation = full.body_pose(full.to_mujoco(q), frame)
            worst = max(worst, np.abs(position - poses[frame].translation).max())
            worst = max(worst, np.abs(rotation - poses[frame].rotation).max())
        position, rotation = arm.body_pose(arm.to_mujoco(q), "right_gripper")
        worst = max(worst, np.abs(position - poses["right_gripper"].translation).max())
        worst = max(worst, np.abs(rotation - poses["right_gripper"].rotation).max())
    assert worst < 1e-9


def test_mujoco_model_text_and_mapping(kin):
    text = mujoco_urdf_text(kin)
    assert ".DAE" not in text and "<visual" not in text
    assert '<compiler fusestatic="false"' in text
    model = build_mujoco_model(kin)
    q = kin.random_q(np.random.default_rng(1))
    assert np.array_equal(model.to_pinocchio(model.to_mujoco(q), np.zeros(kin.nq)), q)
    with pytest.raises(KinematicsError, match="no body 'nowhere'"):
        model.body_pose(model.to_mujoco(q), "nowhere")


def test_jacobian_matches_finite_differences(kin):
    rng = np.random.default_rng(3)
    eps = 1e-7
    for frame in ("right_gripper", "left_hand_camera_link"):
        for _ in range(5):
            q = kin.random_q(rng)
            jacobian = kin.jacobian(q, frame)
            pose = kin.frame_pose(q, frame)
            numeric = np.zeros((6, kin.nq))
            for i in range(kin.nq):
                dq = q.copy()
                dq[i] += eps
                moved = kin.frame_pose(dq, frame)
                numeric[:3, i] = (moved.translation - pose.translation) / eps
                numeric[3:, i] = pin.log3(moved.rotation @ pose.rotation.T) / eps  # world-aligned angular velocity
            assert np.abs(jacobian - numeric).max() < 1e-5


def test_arm_jacobian_and_reference_frames(kin):
    q = kin.random_q(np.random.default_rng(4))
    arm = kin.arm_jacobian(q, "right")
    assert arm.shape == (6, 7)
    assert np.array_equal(arm, kin.jacobian(q, "right_gripper")[:, kin.arm_indices("right")])
    assert np.count_nonzero(kin.jacobian(q, "right_gripper")[:, kin.arm_indices("left")]) == 0
    local = kin.jacobian(q, "right_gripper", "local")
    rotation = kin.frame_pose(q, "right_gripper").rotation
    world_aligned = kin.jacobian(q, "right_gripper")
    assert world_aligned.shape == (6, 19)
    assert np.allclose(rotation @ local[:3], world_aligned[:3]) and np.allclose(rotation @ local[3:], world_aligned[3:])
    with pytest.raises(KinematicsError, match="unknown reference 'body'"):
        kin.jacobian(q, "right_gripper", "body")


def test_unknown_frame_and_pose_helpers(kin):
    with pytest.raises(KinematicsError, match="unknown frame 'right_hand_cam' on robot 'baxter'"):
        kin.frame_pose(kin.home, "right_hand_cam")
    pose = kin.end_effector_pose(kin.home, "right")
    assert se3_from_matrix(pose_matrix(pose)).isApprox(pose)
    with pytest.raises(KinematicsError, match="4x4"):
        se3_from_matrix(np.eye(3))
    position, rotation = Kinematics.pose_error(pose, pose * pin.SE3(pin.utils.rotate("z", 0.01), np.zeros(3)))
    assert position == pytest.approx(0.0, abs=1e-12) and rotation == pytest.approx(0.01)
