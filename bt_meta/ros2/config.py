"""The ROS 2 config: which controllers, joints, topics and frames a robot's bringup offers (YAML, documented in
docs/ros2.md). Without a file, the defaults are what ``bt-meta sim serve --ros2`` uses for the same robot.

Every name is checked against the robot description where it can be: an arm the robot lacks, a joint that is not
that arm's, a frame that is no link of the model, a controller or topic that is no valid ROS name -- each a
:class:`~bt_meta.errors.ConfigError` at ``path:line:column`` (the CLI exits 2).

Offers:

* :class:`ArmConfig` / :class:`Ros2Config` -- the config; ``trajectory_action(arm)`` is
  ``/<controller>/follow_joint_trajectory``
* :func:`default_config` -- the defaults for a robot description
* :func:`load_config` -- a file read over the defaults
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import ConfigError
from bt_meta.world._yaml_nodes import YamlNodeReader

__all__ = ["ArmConfig", "Ros2Config", "default_config", "load_config"]

_NAME = re.compile(r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$")
_TOPICS = ("joint_states", "object_poses", "camera_image", "camera_info", "camera_depth")


@dataclass(frozen=True)
class ArmConfig:
    name: str
    controller: str
    """ros2_control's joint trajectory controller: its action is ``/<controller>/follow_joint_trajectory``."""
    joints: tuple[str, ...]
    gripper_action: str | None
    """``control_msgs/action/GripperCommand`` server (``None``: the arm has no gripper)."""


@dataclass(frozen=True)
class Ros2Config:
    arms: dict[str, ArmConfig]
    base_frame: str
    """frame_id of the poses published and expected (a link of the robot model)."""
    joint_states: str = "/joint_states"
    object_poses: str = "/bt_meta/object_poses"
    """Object poses as ``visualization_msgs/MarkerArray`` (one marker per object, ``ns`` = its name): the served
    simulator publishes the ground truth there; on a robot, a perception node must."""
    camera_image: str = "/bt_meta/camera/image_raw"
    camera_info: str = "/bt_meta/camera/camera_info"
    camera_depth: str = "/bt_meta/camera/depth/image_raw"
    """The top view's depth (``sensor_msgs/Image``, 32FC1 metres along the optical axis, or 16UC1 mm), registered
    to ``camera_image``: the camera perception plugin reads block heights from it."""
    server_timeout: float = 5.0
    """s to wait for every action server at the start (then exit 2, before any motion)."""
    result_timeout: float = 10.0
    """s a goal's result, or a state stamped after it, may take before the connection counts as lost."""
    camera_timeout: float = 5.0
    """s a camera frame stamped after the last motion may take before perception fails naming the topic."""
    path: Path | None = field(default=None, compare=False)

    def trajectory_action(self, arm: str) -> str:
        return f"/{self.arms[arm].controller.strip('/')}/follow_joint_trajectory"


def default_config(robot: Any) -> Ros2Config:
    """The defaults ``bt-meta sim serve --ros2 --robot R`` serves for ``robot`` (a RobotDescription)."""
    arms = {name: ArmConfig(name, f"{name}_arm_controller", tuple(arm.joints),
                            f"/{name}_gripper_controller/gripper_cmd" if arm.gripper is not None else None)
            for name, arm in robot.arms.items()}
    return Ros2Config(arms, robot.base_frame)


class _ConfigFile(YamlNodeReader):
    def __init__(self, path: Path, robot: Any) -> None:
        super().__init__(path)
        self.robot = robot

    def ros_name(self, node: yaml.Node, what: str) -> str:
        name = self.string(node, what)
        if not _NAME.match(name):
            raise self.error(f"{what}: {name!r} is not a valid ROS 2 name", node)
        return name

    def frame(self, node: yaml.Node, what: str) -> str:
        name = self.string(node, what)
        if name not in self.robot.urdf.frames:
            raise self.error(f"{what}: unknown frame {name!r} (no link or joint of robot {self.robot.name!r})", node)
        return name

    def load(self, text: str, base: Ros2Config) -> Ros2Config:
        from bt_meta.safe_yaml import compose_yaml

        root = compose_yaml(text, str(self.path), ConfigError)
        if root is None:
            return dataclasses.replace(base, path=self.path)
        top = self.mapping(root, "the ROS 2 config", {"arms", "topics", "frames", "timeouts"})
        values: dict[str, Any] = {"path": self.path}
        if "arms" in top:
            arms = dict(base.arms)
            for name, (key, node) in self.mapping(top["arms"][1], "arms").items():
                if name not in self.robot.arms:
                    raise self.error(f"arms: robot {self.robot.name!r} has no arm {name!r}; arms: "
                                     f"{', '.join(self.robot.arms)}", key)
                arms[name] = self.arm(name, node, arms[name])
            values["arms"] = arms
        if "topics" in top:
            for name, (_, node) in self.mapping(top["topics"][1], "topics", set(_TOPICS)).items():
                values[name] = self.ros_name(node, f"topics.{name}")
        if "frames" in top:
            frames = self.mapping(top["frames"][1], "frames", {"base"})
            if "base" in frames:
                values["base_frame"] = self.frame(frames["base"][1], "frames.base")
        if "timeouts" in top:
            for name, (_, node) in self.mapping(top["timeouts"][1], "timeouts",
                                                  {"server", "result", "camera"}).items():
                values[f"{name}_timeout"] = self.number(node, f"timeouts.{name}", positive=True)
        return dataclasses.replace(base, **values)

    def arm(self, name: str, node: yaml.Node, base: ArmConfig) -> ArmConfig:
        what = f"arms.{name}"
        entries = self.mapping(node, what, {"controller", "joints", "gripper_action"})
        controller = self.ros_name(entries["controller"][1], f"{what}.controller") if "controller" in entries \
            else base.controller
        joints = base.joints
        if "joints" in entries:
            own = set(self.robot.arm(name).joints)
            listed = []
            for item in self.sequence(entries["joints"][1], f"{what}.joints"):
                joint = self.string(item, f"{what}.joints")
                if joint not in own:
                    known = "joint of the robot's " + name + " arm" if joint in self.robot.home else "joint"
                    raise self.error(f"{what}.joints: unknown {known} {joint!r}; the arm's joints: "
                                     f"{', '.join(self.robot.arm(name).joints)}", item)
                listed.append(joint)
            missing = sorted(own - set(listed))
            if missing:
                raise self.error(f"{what}.joints: the controller must drive every joint of the arm; missing "
                                 f"{', '.join(missing)}", entries["joints"][1])
            joints = tuple(listed)
        gripper = base.gripper_action
        if "gripper_action" in entries:
            value = self.scalar(entries["gripper_action"][1], f"{what}.gripper_action")
            gripper = None if value is None else self.ros_name(entries["gripper_action"][1],
                                                               f"{what}.gripper_action")
        return ArmConfig(name, controller, joints, gripper)


def load_config(path: str | Path | None, robot: Any) -> Ros2Config:
    """The config in ``path`` over :func:`default_config` of ``robot``; ``None``: the defaults."""
    base = default_config(robot)
    if path is None:
        return base
    from bt_meta.user_files import read_user_text

    path = Path(path)
    text = read_user_text(path, what="ROS 2 config", error=ConfigError)
    return _ConfigFile(path, robot).load(text, base)
