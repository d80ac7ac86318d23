"""mink IK for one arm: accuracy, collision-aware acceptance, failure kinds, determinism, misuse."""

from __future__ import annotations

import math

import mink
import numpy as np
import pytest

from bt_meta.errors import KinematicsError
from bt_meta.world.kinematics.collision import pose_from_xyz_rpy
from bt_meta.world.kinematics.ik import COLLISION, REACHABILITY, InverseKinematics, _Run
from bt_meta.world.robot.description import load_robot


@pytest.fixture(scope="module")
def ik(kin, checker) -> InverseKinematics:
    return InverseKinematics(kin, checker)


@pytest.fixture
def table(checker):
    checker.add_box("table", (0.8, 1.4, 0.1), (0.8, 0.0, -0.2))  # top at z = -0.15
    yield "table"
    checker.clear_scene()


def reachable_targets(kin, checker, n, seed):
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        q = kin.random_q(rng, "right")
        if checker.check(q) is None:
            out.append(kin.end_effector_pose(q, "right"))
    return out


def test_reachable_targets_are_solved_within_tolerance_and_collision_free(kin, checker, ik):
    settings = kin.robot.ik
    for target in reachable_targets(kin, checker, 15, seed=21):
        result = ik.solve("right", target)
        assert result.success, result.message
        assert result.kind is None and result.q is not None
        position, rotation = kin.pose_error(kin.end_effector_pose(result.q, "right"), target)
        assert position <= settings.position_tolerance and rotation <= settings.orientation_tolerance
        assert result.position_error == pytest.approx(position, abs=1e-9)
        assert checker.check(result.q) is None
        assert kin.within_limits(result.q)
        others = np.setdiff1d(np.arange(kin.nq), kin.arm_indices("right"))
        assert np.array_equal(result.q[others], kin.home[others])
        assert result.iterations >= 0 and result.attempts >= 1 and result.time > 0


def test_other_joints_keep_their_start_values(kin, ik):
    start = kin.q_from_dict({"left_s0": 0.4, "head_pan": -0.3}, kin.home)
    target = kin.end_effector_pose(kin.q_from_dict({"right_e1": 1.5, "right_w1": 0.8}, kin.home), "right")
    result = ik.solve("right", target, start)
    assert result.success
    assert result.q[kin.q_index("left_s0")] == 0.4 and result.q[kin.q_index("head_pan")] == -0.3


def test_far_target_is_a_reachability_failure_without_searching(ik):
    target = pose_from_xyz_rpy(2.0, -0.2, 0.1, math.pi, 0.0, 0.0)
    result = ik.solve("right", target)
    assert not result.success and result.q is None
    assert result.kind == REACHABILITY
    assert ("no IK solution for right_gripper at [2.0, -0.2, 0.1] (base frame base): 1.937 m from the right arm's "
            "first joint") in result.message
    assert "beyond its reach of 1.414 m" in result.message
    assert result.evidence["target_xyz"] == [2.0, -0.2, 0.1] and result.evidence["target_frame"] == "base"
    assert result.evidence["distance"] > result.evidence["reach"]
    assert result.attempts == 0 and result.iterations == 0


def test_reach_bound_holds(kin, ik):
    shoulder, reach = ik._arm("right").reach["right_gripper"]
    rng = np.random.default_rng(2)
    farthest = max(
        np.linalg.norm(kin.end_effector_pose(kin.random_q(rng, "right"), "right").translation - shoulder)
        for _ in range(2000)
    )
    assert reach - 0.02 < farthest <= reach


def test_unreachable_target_within_reach_is_searched_then_classified(ik):
    shoulder, _ = ik._arm("right").reach["right_gripper"]
    x, y, z = shoulder + np.array([0.05, -0.05, 0.0])
    target = pose_from_xyz_rpy(x, y, z, 0.0, 0.0, 0.0)  # the hand cannot fold back onto its shoulder
    result = ik.solve("right", target)
    assert not result.success and result.kind == REACHABILITY
    assert result.attempts == load_robot("baxter").ik.max_attempts
    assert "after 40 attempts; best residual" in result.message
    assert result.evidence["best_position_error"] > 0.01
    assert len(result.evidence["best_q"]) == 19


def test_target_inside_the_table_is_a_collision_failure_naming_the_pair(ik, table):
    target = pose_from_xyz_rpy(0.7, -0.2, -0.17, math.pi, 0.0, 0.0)  # fingertips 2 cm into the table top
    result = ik.solve("right", target)
    assert not result.success and result.kind == COLLISION
    assert result.evidence["pair"][1] == "table"
    assert result.evidence["pair"][0].startswith("r_gripper")
    assert f"collides: {result.evidence['pair'][0]} <-> table" in result.message
    assert result.evidence["colliding_solutions"] >= 1
    assert result.evidence["escapes_tried"] == 0  # fingers move rigidly with the hand: no self-motion frees them
    # The same target without collision checking is solvable: the rejection is what made it fail.
    unchecked = ik.solve("right", target, check_collisions=False)
    assert unchecked.success
    contact = ik.collision.check(unchecked.q)
    assert contact is not None and contact.second == "table"
    # Just above the table it succeeds.
    assert ik.solve("right", pose_from_xyz_rpy(0.7, -0.2, -0.12, math.pi, 0.0, 0.0)).success


def test_self_motion_escapes_an_elbow_collision(kin, checker, ik):
    # A collision-free pose in front of the face: many IK solutions put the forearm into the head's sphere.
    joints = kin.robot.arms["right"].joints
    free = kin.q_from_dict(dict(zip(joints, [-0.82, -0.94, 2.53, 2.51, -2.49, 1.79, -1.43], strict=True)), kin.home)
    assert checker.check(free) is None
    target = kin.end_effector_pose(free, "right")
    colliding = ik.solve("right", target, seed=0, check_collisions=False)
    contact = checker.check(colliding.q)
    assert contact is not None and contact.pair == ("collision_head_link_1", "right_lower_forearm")
    solver = ik._arm("right")
    task, body = ik._task(solver, "right", "right_gripper")
    run = _Run(ik, "right", solver, task, body, "right_gripper", target, kin.home.copy(), 0, True)
    run.colliding = [(contact, colliding.q)] * kin.robot.ik.escape_after
    solver.configuration.update(solver.mj.to_mujoco(colliding.q))
    escaped = run.escape(contact)
    assert escaped is not None and checker.check(escaped) is None
    position, rotation = kin.pose_error(kin.end_effector_pose(escaped, "right"), target)
    assert position <= kin.robot.ik.position_tolerance and rotation <= kin.robot.ik.orientation_tolerance
    # The whole solve finds a collision-free solution too.
    result = ik.solve("right", target, seed=0)
    assert result.success and checker.check(result.q) is None


def test_same_seed_same_solution(kin, checker, ik):
    for target in reachable_targets(kin, checker, 60, seed=5):
        first = ik.solve("right", target, seed=3)
        if first.attempts > 2:  # it needed seeded random restarts
            break
    else:
        pytest.fail("no target among 60 needed random restarts")
    again = ik.solve("right", target, seed=3)
    assert again.success == first.success and again.attempts == first.attempts
    assert np.array_equal(again.q, first.q)
    assert again.iterations == first.iterations


def test_misuse_raises_kinematics_errors(kin, ik):
    target = kin.end_effector_pose(kin.home, "right")
    with pytest.raises(KinematicsError, match="unknown frame 'right_grip'"):
        ik.solve("right", target, frame="right_grip")
    with pytest.raises(KinematicsError, match="no arm 'middle'"):
        ik.solve("middle", target)
    with pytest.raises(KinematicsError, match="'left_gripper' is not moved by arm 'right'"):
        ik.solve("right", target, frame="left_gripper")
    with pytest.raises(KinematicsError, match="'right_endpoint' is not a link"):
        ik.solve("right", target, frame="right_endpoint")
    with pytest.raises(KinematicsError, match="a pose is an SE3"):
        ik.solve("right", [1.0, 2.0])


def test_other_frames_of_the_arm_can_be_targets(kin, ik):
    q = kin.q_from_dict({"right_s0": -0.3, "right_e1": 1.2}, kin.home)
    target = kin.frame_pose(q, "right_hand_camera_link")
    result = ik.solve("right", target, frame="right_hand_camera_link")
    assert result.success
    position, _ = kin.pose_error(kin.frame_pose(result.q, "right_hand_camera_link"), target)
    assert position <= kin.robot.ik.position_tolerance


def test_each_step_is_minks_step(kin, ik):
    solver = ik._arm("right")
    task, _ = ik._task(solver, "right", "right_gripper")
    rng = np.random.default_rng(9)
    for _ in range(10):
        goal = kin.end_effector_pose(kin.random_q(rng, "right"), "right")
        task.set_target(mink.SE3.from_matrix(goal.homogeneous))
        solver.configuration.update(solver.mj.to_mujoco(kin.random_q(rng, "right")))
        assert np.allclose(ik._step(solver, task), ik.mink_step("right"), atol=1e-10)


@pytest.mark.slow
def test_benchmark_runs_and_reports(kin):
    from bt_meta.bench.ik import run_benchmark

    report = run_benchmark(n=12, seed=1, arm="right", pybullet_calls=10)
    assert report["n"] == 12
    assert report["ours"]["success"] == 1.0
    assert report["ours"]["every_returned_solution_collision_free"]
    assert 0.0 <= report["pybullet"]["success"] <= 1.0
    assert report["ratio_mean_time_pybullet_over_ours"] > 0
