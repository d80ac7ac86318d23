"""Fixed links merged in pybullet: every URDF link name still resolves to the same frame."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest

from bt_meta.world.simulation.robot_links import merged_frames, read_joints, subtree
from bt_meta.world.simulation.sim import Simulation
from bt_meta.world.simulation.sim_world import quiet_stdout

_URDF = """<robot name="toy">
  <link name="base"/>
  <link name="arm"/>
  <link name="tool"/>
  <link name="tip"/>
  <link name="finger"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>
  <joint name="tool_mount" type="fixed"><parent link="arm"/><child link="tool"/>
    <origin xyz="0.3 0 0" rpy="0 0 1.5707963267948966"/></joint>
  <joint name="tip_mount" type="fixed"><parent link="tool"/><child link="tip"/>
    <origin xyz="0 0.1 0" rpy="0.5 0 0"/></joint>
  <joint name="slide" type="prismatic"><parent link="tool"/><child link="finger"/>
    <origin xyz="0 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.1"/></joint>
</robot>
"""


def test_merged_frames_compose_the_fixed_joints(tmp_path):
    path = tmp_path / "toy.urdf"
    path.write_text(_URDF, encoding="utf-8")
    joints = read_joints(path)
    frames = merged_frames(joints, {"base", "arm", "finger"})
    assert set(frames) == {"tool", "tip"}
    kept, tool = frames["tool"]
    assert kept == "arm"
    np.testing.assert_allclose(tool[:3, 3], [0.3, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(tool[:3, 0], [0.0, 1.0, 0.0], atol=1e-12)  # yaw 90 degrees: x turns to y
    kept, tip = frames["tip"]
    assert kept == "arm"
    # tool_mount then tip_mount: 0.1 along the tool's y, which is the arm's -x.
    np.testing.assert_allclose(tip[:3, 3], [0.2, 0.0, 0.0], atol=1e-12)
    c, s = np.cos(0.5), np.sin(0.5)
    np.testing.assert_allclose(tip[:3, :3], tool[:3, :3] @ [[1, 0, 0], [0, c, -s], [0, s, c]], atol=1e-12)
    assert subtree(joints, "tool") == {"tool", "tip", "finger"}


def test_a_merged_link_below_a_moving_joint_is_not_accepted(tmp_path):
    path = tmp_path / "toy.urdf"
    path.write_text(_URDF, encoding="utf-8")
    with pytest.raises(Exception, match="fixed"):
        merged_frames(read_joints(path), {"base", "finger"})  # "arm" hangs from a revolute joint


def test_the_merged_baxter_has_the_frames_and_hand_of_the_unmerged_one():
    with quiet_stdout():
        split = Simulation(seed=0, merge_fixed_links=False)
        merged = Simulation(seed=0, merge_fixed_links=True)
    try:
        assert pybullet.getNumJoints(merged.robot_id, physicsClientId=merged.client) < pybullet.getNumJoints(
            split.robot_id, physicsClientId=split.client)
        rng = np.random.default_rng(3)
        q = {j: float(rng.uniform(max(-2.0, lo), min(2.0, hi)))
             for j, (lo, hi) in ((j, split.joint_limits(j)) for j in split.movable_joints)}
        split.set_joint_positions(q)
        merged.set_joint_positions(q)
        assert set(merged._link_index) == set(split._link_index)
        for name in split._link_index:
            np.testing.assert_allclose(merged.link_transform(name), split.link_transform(name), atol=1e-6,
                                       err_msg=name)
        for arm in split.robot.arms:
            # The same shapes belong to the hand: the hand's base now lives on the wrist link.
            hand = {merged._link_name[i] for i in merged._hand_links[arm]}
            wrist = merged._link_name[merged.joint_index(merged.robot.arm(arm).joints[-1])]
            assert wrist in hand
            assert {split._link_name[i] for i in split._hand_links[arm]} >= hand - {wrist}
            assert len(hand) == 3  # the wrist and two fingers
    finally:
        split.close()
        merged.close()


def test_merging_is_chosen_by_the_environment(monkeypatch):
    for value, expected in (("1", True), ("0", False)):
        monkeypatch.setenv("BT_META_MERGE_FIXED_LINKS", value)
        with quiet_stdout():
            sim = Simulation(seed=0)
        try:
            assert sim.merge_fixed_links is expected
            assert (pybullet.getNumJoints(sim.robot_id, physicsClientId=sim.client) < 56) is expected
        finally:
            sim.close()
