"""Conversions between ROS 2 messages and the numbers bt-meta works with (stamps, 4x4 poses, trajectories).

Offers:

* :func:`to_stamp` / :func:`nanoseconds` -- seconds <-> ``builtin_interfaces/Time`` (integer nanoseconds)
* :func:`to_duration` / :func:`duration_seconds` -- seconds <-> ``builtin_interfaces/Duration``
* :func:`pose_message` / :func:`pose_matrix` -- 4x4 transform <-> ``geometry_msgs/Pose``
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pybullet

__all__ = ["duration_seconds", "nanoseconds", "pose_matrix", "pose_message", "to_duration", "to_stamp"]


def to_stamp(seconds: float) -> Any:
    from builtin_interfaces.msg import Time

    total = round(seconds * 1e9)
    return Time(sec=total // 1_000_000_000, nanosec=total % 1_000_000_000)


def nanoseconds(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def to_duration(seconds: float) -> Any:
    from builtin_interfaces.msg import Duration

    total = round(seconds * 1e9)
    return Duration(sec=total // 1_000_000_000, nanosec=total % 1_000_000_000)


def duration_seconds(duration: Any) -> float:
    return int(duration.sec) + int(duration.nanosec) * 1e-9


def pose_message(transform: np.ndarray) -> Any:
    from geometry_msgs.msg import Point, Pose, Quaternion

    x, y, z, w = _quaternion(transform[:3, :3])
    p = transform[:3, 3]
    return Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                orientation=Quaternion(x=x, y=y, z=z, w=w))


def _quaternion(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix (Shepperd's method, the largest diagonal term first)."""
    m = rotation
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0.0:
        s = 2.0 * np.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return float(x), float(y), float(z), float(w)


def pose_matrix(pose: Any) -> np.ndarray:
    q = pose.orientation
    out = np.eye(4)
    out[:3, :3] = np.asarray(pybullet.getMatrixFromQuaternion([q.x, q.y, q.z, q.w]), dtype=float).reshape(3, 3)
    out[:3, 3] = [pose.position.x, pose.position.y, pose.position.z]
    return out
