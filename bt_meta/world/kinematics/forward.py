"""Forward kinematics and Jacobians of a robot description, with Pinocchio.

Offers:

* :class:`Kinematics` -- the Pinocchio model of a :class:`~bt_meta.world.robot.description.RobotDescription`: joint
  order,
  arm-joint index maps, home and SRDF reference configurations, frame poses (FK) and Jacobians
* :func:`pose_matrix` / :func:`se3_from_matrix` -- 4x4 homogeneous matrices to and from ``pinocchio.SE3``

Configurations ``q`` are numpy vectors in Pinocchio's joint order (``Kinematics.joint_names``); every movable
joint of Baxter is revolute or prismatic, so ``nq == nv`` and index ``i`` of ``q`` is joint ``joint_names[i]``.
Poses are in the robot's base frame. Misuse (an unknown frame, arm or joint, a configuration of the wrong size)
raises :class:`bt_meta.errors.KinematicsError`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from collections.abc import Iterable, Mapping

import numpy as np
import pinocchio as pin

from bt_meta.errors import KinematicsError
from bt_meta.world.robot.description import RobotDescription

__all__ = ["Kinematics", "pose_matrix", "se3_from_matrix"]


_REFERENCE = {
    "world": pin.ReferenceFrame.WORLD,
    "local": pin.ReferenceFrame.LOCAL,
    "local_world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
}


def pose_matrix(pose: pin.SE3) -> np.ndarray:
    return np.array(pose.homogeneous)


def se3_from_matrix(matrix: np.ndarray) -> pin.SE3:
    matrix = np.asarray(matrix, dtype=float)
    if matrix.shape != (4, 4):
        raise KinematicsError(f"a pose matrix must be 4x4, got shape {matrix.shape}")
    return pin.SE3(matrix[:3, :3].copy(), matrix[:3, 3].copy())


class Kinematics:
    """The robot's Pinocchio model and the name-to-index maps everything else uses."""

    def __init__(self, robot: RobotDescription) -> None:
        self.robot = robot
        self.model: pin.Model = pin.buildModelFromUrdf(str(robot.urdf_path))
        self.data: pin.Data = self.model.createData()
        if self.model.nq != self.model.nv:
            raise KinematicsError("only robots with revolute and prismatic joints are supported (nq != nv)")
        self.joint_names: tuple[str, ...] = tuple(self.model.names[i] for i in range(1, self.model.njoints))
        self._q_index = {name: self.model.idx_qs[self.model.getJointId(name)] for name in self.joint_names}
        self.lower = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper = np.array(self.model.upperPositionLimit, dtype=float)
        for name, (low, high) in robot.joint_limits.items():
            if name in self._q_index:
                self.lower[self._q_index[name]] = low
                self.upper[self._q_index[name]] = high
        self._arm_indices = {arm: np.array([self._q_index[j] for j in a.joints]) for arm, a in robot.arms.items()}
        self.home = self.q_from_dict(robot.home)
        self.reference = self._srdf_reference()

    # -- names and indices -------------------------------------------------------------------------------------

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    def q_index(self, joint: str) -> int:
        try:
            return int(self._q_index[joint])
        except KeyError:
            raise KinematicsError(f"unknown joint {joint!r}; movable joints: {', '.join(self.joint_names)}") from None

    def arm_indices(self, arm: str) -> np.ndarray:
        """Indices in ``q`` of an arm's joints, in the arm's order (shoulder to wrist)."""
        try:
            return self._arm_indices[arm].copy()
        except KeyError:
            raise KinematicsError(
                f"robot {self.robot.name!r} has no arm {arm!r}; arms: {', '.join(self.robot.arms)}"
            ) from None

    def frame_id(self, frame: str) -> int:
        if not self.model.existFrame(frame):
            raise KinematicsError(f"unknown frame {frame!r} on robot {self.robot.name!r}")
        return int(self.model.getFrameId(frame))

    def end_effector(self, arm: str) -> str:
        return self.robot.arm(arm).end_effector

    # -- configurations ----------------------------------------------------------------------------------------

    def check_q(self, q: Iterable[float]) -> np.ndarray:
        array = np.asarray(q, dtype=float)
        if array.shape != (self.nq,):
            raise KinematicsError(
                f"a configuration has {self.nq} values (joints {', '.join(self.joint_names)}), got shape {array.shape}"
            )
        return array

    def q_from_dict(self, values: Mapping[str, float], base: np.ndarray | None = None) -> np.ndarray:
        """A configuration from joint name -> value; joints not named keep ``base`` (default: all zero)."""
        q = np.zeros(self.nq) if base is None else self.check_q(base).copy()
        for name, value in values.items():
            q[self.q_index(name)] = float(value)
        return q

    def q_to_dict(self, q: np.ndarray) -> dict[str, float]:
        q = self.check_q(q)
        return {name: float(q[self._q_index[name]]) for name in self.joint_names}

    def within_limits(self, q: np.ndarray, tolerance: float = 1e-9) -> bool:
        q = self.check_q(q)
        return bool(np.all(q >= self.lower - tolerance) and np.all(q <= self.upper + tolerance))

    def clamp(self, q: np.ndarray) -> np.ndarray:
        return np.clip(self.check_q(q), self.lower, self.upper)

    def random_q(self, rng: np.random.Generator, arm: str | None = None, base: np.ndarray | None = None) -> np.ndarray:
        """Uniform in the joint limits: every joint, or only ``arm``'s joints on top of ``base`` (default home)."""
        if arm is None:
            return rng.uniform(self.lower, self.upper)
        q = (self.home if base is None else self.check_q(base)).copy()
        idx = self.arm_indices(arm)
        q[idx] = rng.uniform(self.lower[idx], self.upper[idx])
        return q

    def _srdf_reference(self) -> np.ndarray:
        """The SRDF's first ``group_state`` (Baxter's "neutral"), names stripped of the SRDF prefix; else zero."""
        q = np.zeros(self.nq)
        path = self.robot.srdf_path
        if path is None:
            return q
        root = ElementTree.fromstring(path.read_text(encoding="utf-8"))
        state = root.find("group_state")
        if state is None:
            return q
        prefix = self.robot.srdf_joint_prefix
        for joint in state.findall("joint"):
            name = joint.get("name", "")
            if prefix and name.startswith(prefix):
                name = name[len(prefix) :]
            if name in self._q_index:
                q[self._q_index[name]] = float(joint.get("value", "0").split()[0])
        return q

    # -- forward kinematics ------------------------------------------------------------------------------------

    def forward(self, q: np.ndarray) -> None:
        """Update every frame placement of ``self.data`` for ``q`` (then read ``data.oMf``)."""
        pin.framesForwardKinematics(self.model, self.data, self.check_q(q))

    def frame_pose(self, q: np.ndarray, frame: str) -> pin.SE3:
        """Pose of ``frame`` in the base frame at configuration ``q``."""
        fid = self.frame_id(frame)
        self.forward(q)
        return pin.SE3(self.data.oMf[fid])

    def frame_poses(self, q: np.ndarray, frames: Iterable[str]) -> dict[str, pin.SE3]:
        ids = {frame: self.frame_id(frame) for frame in frames}
        self.forward(q)
        return {frame: pin.SE3(self.data.oMf[fid]) for frame, fid in ids.items()}

    def end_effector_pose(self, q: np.ndarray, arm: str) -> pin.SE3:
        return self.frame_pose(q, self.end_effector(arm))

    def jacobian(self, q: np.ndarray, frame: str, reference: str = "local_world_aligned") -> np.ndarray:
        """6 x nv Jacobian of ``frame`` (linear rows first); ``reference`` is world, local or local_world_aligned."""
        if reference not in _REFERENCE:
            raise KinematicsError(f"unknown reference {reference!r}; expected one of {', '.join(_REFERENCE)}")
        fid = self.frame_id(frame)
        q = self.check_q(q)
        return np.array(pin.computeFrameJacobian(self.model, self.data, q, fid, _REFERENCE[reference]))

    def arm_jacobian(self, q: np.ndarray, arm: str, reference: str = "local_world_aligned") -> np.ndarray:
        """6 x 7 Jacobian of an arm's end effector with respect to that arm's joints only."""
        return self.jacobian(q, self.end_effector(arm), reference)[:, self.arm_indices(arm)]

    @staticmethod
    def pose_error(current: pin.SE3, target: pin.SE3) -> tuple[float, float]:
        """(position error in m, orientation error in rad) between two poses."""
        position = float(np.linalg.norm(current.translation - target.translation))
        rotation = float(np.linalg.norm(pin.log3(current.rotation.T @ target.rotation)))
        return position, rotation
