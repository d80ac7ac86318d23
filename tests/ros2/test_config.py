"""The ROS 2 config: defaults from the robot description, and located errors for unknown arms, joints, frames and
names that are not ROS names (no ROS needed)."""

from __future__ import annotations

import pytest

from bt_meta.errors import ConfigError
from bt_meta.ros2.config import default_config, load_config
from bt_meta.world.robot.description import load_robot


def test_defaults_are_what_sim_serve_uses():
    config = default_config(load_robot("baxter"))
    assert config.trajectory_action("right") == "/right_arm_controller/follow_joint_trajectory"
    assert config.arms["right"].joints == load_robot("baxter").arm("right").joints
    assert config.arms["left"].gripper_action == "/left_gripper_controller/gripper_cmd"
    assert config.base_frame == "base" and config.joint_states == "/joint_states"


@pytest.mark.parametrize(("text", "where", "message"), [
    ("arms:\n  middle: {controller: c}\n", "2:3", "robot 'baxter' has no arm 'middle'"),
    ("arms:\n  right:\n    joints: [right_s0, left_s0]\n", "3:24", "unknown joint of the robot's right arm"),
    ("arms:\n  right:\n    joints: [right_s0]\n", "3:13", "missing right_e0"),
    ("arms:\n  right: {controller: 'a b'}\n", "2:23", "not a valid ROS 2 name"),
    ("frames: {base: nowhere}\n", "1:16", "unknown frame 'nowhere'"),
    ("topics: {odom: /odom}\n", "1:10", "unknown key 'odom'"),
    ("timeouts: {server: -1}\n", "1:20", "must be positive"),
])
def test_bad_configs_name_path_line_column(tmp_path, text, where, message):
    path = tmp_path / "ros2.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_config(path, load_robot("baxter"))
    assert caught.value.location_message().startswith(f"{path}:{where}: ") and message in str(caught.value)


def test_a_config_overrides_the_defaults(tmp_path):
    path = tmp_path / "ros2.yaml"
    path.write_text("arms:\n  right: {controller: scaled_joint_trajectory_controller, gripper_action: null}\n"
                    "topics: {object_poses: /perception/objects}\ntimeouts: {server: 20}\n")
    config = load_config(path, load_robot("baxter"))
    assert config.trajectory_action("right") == "/scaled_joint_trajectory_controller/follow_joint_trajectory"
    assert config.arms["right"].gripper_action is None and config.object_poses == "/perception/objects"
    assert config.server_timeout == 20.0 and config.path == path


def test_the_camera_topics_and_timeout_are_configured(tmp_path):
    path = tmp_path / "ros2.yaml"
    path.write_text("topics: {camera_depth: /camera/aligned_depth_to_color/image_raw}\ntimeouts: {camera: 2.5}\n")
    config = load_config(path, load_robot("baxter"))
    assert config.camera_depth == "/camera/aligned_depth_to_color/image_raw" and config.camera_timeout == 2.5
    assert default_config(load_robot("baxter")).camera_depth == "/bt_meta/camera/depth/image_raw"
    path.write_text("timeouts: {camera: 0}\n")
    with pytest.raises(ConfigError, match="must be positive"):
        load_config(path, load_robot("baxter"))
