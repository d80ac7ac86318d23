"""(x, y, z, roll, pitch, yaw) poses and 4x4 transforms: what the skills and the simulation both speak.

A module of its own so that the skills (:mod:`bt_meta.world.skills`) need not import the simulation package,
whose World imports the skills' registry.

Offers:

* :data:`Pose6` -- a pose as six floats (metres, radians)
* :func:`rpy_to_matrix`, :func:`pose_to_matrix`, :func:`matrix_to_pose` -- conversions
* :class:`PoseError` -- a pose of the wrong length
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bt_meta.errors import BtMetaError

__all__ = ["Pose6", "PoseError", "axis_angle_matrix", "matrix_to_pose", "pose_to_matrix", "rpy_to_matrix"]

Pose6 = tuple[float, float, float, float, float, float]


class PoseError(BtMetaError):
    """A pose that is not six numbers."""


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation for fixed-axis X-Y-Z angles (R = Rz(yaw) Ry(pitch) Rx(roll)), pybullet's and ROS's convention."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def axis_angle_matrix(axis: Sequence[float] | np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` (radians) about ``axis`` (any length; a zero axis gives the identity), by Rodrigues."""
    a = np.asarray(axis, float)
    x, y, z = a / (float(np.linalg.norm(a)) or 1.0)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def pose_to_matrix(pose: Sequence[float]) -> np.ndarray:
    """4x4 homogeneous transform of a (x, y, z, roll, pitch, yaw) pose."""
    if len(pose) != 6:
        raise PoseError(f"a pose has 6 numbers (x, y, z, roll, pitch, yaw), got {len(pose)}")
    out = np.eye(4)
    out[:3, :3] = rpy_to_matrix(pose[3], pose[4], pose[5])
    out[:3, 3] = pose[:3]
    return out


def matrix_to_pose(matrix: np.ndarray) -> Pose6:
    """(x, y, z, roll, pitch, yaw) of a 4x4 transform; at pitch = +-90 degrees roll is reported as 0."""
    r = matrix[:3, :3]
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(r[2, 0]) < 1.0 - 1e-9:
        roll = math.atan2(r[2, 1], r[2, 2])
        yaw = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: fold roll into yaw
        roll = 0.0
        yaw = math.atan2(-r[0, 1], r[1, 1])
    x, y, z = (float(v) for v in matrix[:3, 3])
    return (x, y, z, roll, pitch, yaw)
