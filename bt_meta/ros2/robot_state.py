"""What the ROS 2 world knows of the robot: the latest ``/joint_states`` and object poses, each with its stamp, and
a wait for both to be stamped at or after a time (the state after a goal, not a stale one).

Joint states are merged by name (a robot may publish its arm and gripper joints apart); object poses come as a
``visualization_msgs/MarkerArray`` with one marker per object, ``ns`` its name, and one LINE_LIST marker per
magnetic join (:mod:`~bt_meta.ros2.state_publishers`): each message replaces the joins known before, so a join is
as fresh as the poses it came with.

Offers:

* :class:`RobotState` -- ``wait_until(stamp_ns, timeout)``, ``joints()``, ``objects()``, ``joins()``, ``stamp()``
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from bt_meta.ros2.messages import nanoseconds, pose_matrix
from bt_meta.ros2.state_publishers import JOIN_NAMESPACE

__all__ = ["RobotState"]


class RobotState:
    def __init__(self, node: Any, config: Any, callback_group: Any = None) -> None:
        from sensor_msgs.msg import JointState
        from visualization_msgs.msg import MarkerArray

        self._condition = threading.Condition()
        self._joints: dict[str, float] = {}
        self._objects: dict[str, np.ndarray] = {}
        self._joins: set[tuple[str, str]] = set()
        self._joint_stamp = -1
        self._object_stamp = -1
        self.frame = config.base_frame
        self.wrong_frames: set[str] = set()
        self.tap: Any = None
        """``tap(topic, message)`` sees every message received (the MCAP recording), else ``None``."""
        self._topics = (config.joint_states, config.object_poses)
        node.create_subscription(JointState, config.joint_states, self._on_joints, 10,
                                 callback_group=callback_group)
        node.create_subscription(MarkerArray, config.object_poses, self._on_objects, 10,
                                 callback_group=callback_group)

    def _on_joints(self, message: Any) -> None:
        if self.tap is not None:
            self.tap(self._topics[0], message)
        with self._condition:
            self._joints.update(zip(message.name, (float(v) for v in message.position), strict=False))
            self._joint_stamp = max(self._joint_stamp, nanoseconds(message.header.stamp))
            self._condition.notify_all()

    def _on_objects(self, message: Any) -> None:
        if self.tap is not None:
            self.tap(self._topics[1], message)
        with self._condition:
            stamp = self._object_stamp
            joins: set[tuple[str, str]] = set()
            for marker in message.markers:
                if marker.type == marker.LINE_LIST and marker.ns == JOIN_NAMESPACE:
                    names = marker.text.split("\n")
                    if len(names) == 2:
                        joins.add((min(names), max(names)))
                    continue
                if marker.header.frame_id != self.frame:
                    self.wrong_frames.add(marker.header.frame_id)
                    continue
                self._objects[marker.ns] = pose_matrix(marker.pose)
                stamp = max(stamp, nanoseconds(marker.header.stamp))
            self._joins = joins
            self._object_stamp = stamp if message.markers else max(stamp, 0)
            self._condition.notify_all()

    def stamp(self) -> int:
        """The older of the two latest stamps (ns); -1 before both arrived."""
        with self._condition:
            return min(self._joint_stamp, self._object_stamp)

    def wait_until(self, stamp: int, timeout: float) -> bool:
        """Wait until joint states and object poses stamped at or after ``stamp`` (ns) arrived."""
        deadline = time.monotonic() + timeout
        with self._condition:
            while min(self._joint_stamp, self._object_stamp) < stamp:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._condition.wait(min(left, 0.1))
            return True

    def joints(self) -> dict[str, float]:
        with self._condition:
            return dict(self._joints)

    def objects(self) -> dict[str, np.ndarray]:
        with self._condition:
            return {name: pose.copy() for name, pose in self._objects.items()}

    def joins(self) -> set[tuple[str, str]]:
        """The magnetically joined pairs of the latest object-pose message, each sorted by name."""
        with self._condition:
            return set(self._joins)
