"""A MuJoCo model compiled from the robot's URDF, for mink (which works on MuJoCo models only).

Offers:

* :func:`build_mujoco_model` -- the whole robot, or one arm's chain with every other joint frozen
* :class:`MujocoModel` -- the ``mujoco.MjModel`` with the name maps between its ``qpos`` and Pinocchio's ``q``
* :func:`mujoco_urdf_text` -- the URDF text MuJoCo compiles: mesh geometry and visuals stripped, a
  ``<mujoco><compiler fusestatic="false"/></mujoco>`` block injected so that every URDF link stays a body

MuJoCo orders joints differently from Pinocchio, so joints are always mapped by name. An arm model keeps only
that arm's joints movable, which is exact for the end effector as long as no other movable joint lies between the
base and the arm (checked) -- and it makes each IK iteration cheaper (7 DoF instead of 19).
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass

import mujoco
import numpy as np

from bt_meta.errors import KinematicsError
from bt_meta.model_cache import cached, file_signature
from bt_meta.world.kinematics.forward import Kinematics

__all__ = ["MujocoModel", "build_mujoco_model", "mujoco_urdf_text"]


@dataclass
class MujocoModel:
    model: mujoco.MjModel
    joint_names: tuple[str, ...]
    """Movable joints in MuJoCo ``qpos`` order."""
    pin_indices: np.ndarray
    """``pin_indices[i]`` is the index in Pinocchio's ``q`` of MuJoCo joint ``joint_names[i]``."""

    def to_mujoco(self, q: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos`` from a Pinocchio configuration."""
        return np.asarray(q, dtype=float)[self.pin_indices]

    def to_pinocchio(self, qpos: np.ndarray, base: np.ndarray) -> np.ndarray:
        """Pinocchio ``q``: ``base`` with this model's joints replaced by ``qpos``."""
        q = np.array(base, dtype=float)
        q[self.pin_indices] = qpos
        return q

    def body_pose(self, qpos: np.ndarray, body: str) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation matrix) of a body at ``qpos``; for tests and checks, not for inner loops."""
        data = mujoco.MjData(self.model)
        data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, data)
        body_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, body)
        if body_id < 0:
            raise KinematicsError(f"MuJoCo model has no body {body!r}")
        return data.xpos[body_id].copy(), data.xmat[body_id].reshape(3, 3).copy()


def mujoco_urdf_text(kinematics: Kinematics, frozen: set[str] | None = None) -> str:
    """The robot's URDF made compilable by MuJoCo, with the joints in ``frozen`` turned into fixed joints."""
    root = ElementTree.fromstring(kinematics.robot.urdf_path.read_text(encoding="utf-8"))
    for link in root.findall("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
        for collision in link.findall("collision"):
            if collision.find("geometry/mesh") is not None:
                link.remove(collision)
    for joint in root.findall("joint"):
        if frozen and joint.get("name") in frozen:
            joint.set("type", "fixed")
            for child in ("limit", "mimic", "dynamics", "axis"):
                for element in joint.findall(child):
                    joint.remove(element)
        else:
            for mimic in joint.findall("mimic"):
                joint.remove(mimic)  # MuJoCo's URDF importer ignores it anyway; IK treats fingers independently
    for old in root.findall("mujoco"):
        root.remove(old)
    extension = ElementTree.SubElement(root, "mujoco")
    ElementTree.SubElement(extension, "compiler", {"fusestatic": "false", "discardvisual": "true"})
    return ElementTree.tostring(root, encoding="unicode")


def build_mujoco_model(kinematics: Kinematics, arm: str | None = None) -> MujocoModel:
    """The MuJoCo model of the whole robot, or of one arm with every other joint frozen at zero.

    Compiled once per process for the same URDF, arm and joint ranges (:mod:`bt_meta.model_cache`); each
    caller gets its own copy of the ``MjModel``.
    """
    key = ("mujoco model", file_signature(kinematics.robot.urdf_path), arm, tuple(kinematics.joint_names),
           kinematics.lower.tobytes(), kinematics.upper.tobytes())
    compiled = cached(key, lambda: _compile(kinematics, arm))
    return MujocoModel(copy.copy(compiled.model), compiled.joint_names, compiled.pin_indices.copy())


def _compile(kinematics: Kinematics, arm: str | None) -> MujocoModel:
    frozen: set[str] = set()
    if arm is not None:
        arm_joints = set(kinematics.robot.arm(arm).joints)
        model = kinematics.model
        ee_joint = model.frames[kinematics.frame_id(kinematics.end_effector(arm))].parentJoint
        for joint_id in model.supports[ee_joint]:
            name = model.names[joint_id]
            if joint_id != 0 and name not in arm_joints:
                raise KinematicsError(
                    f"joint {name!r} moves arm {arm!r} but is not one of its joints: an arm-only model would be wrong"
                )
        frozen = set(kinematics.joint_names) - arm_joints
    text = mujoco_urdf_text(kinematics, frozen)
    try:
        mj_model = mujoco.MjModel.from_xml_string(text)
    except ValueError as error:
        raise KinematicsError(f"MuJoCo could not compile {kinematics.robot.urdf_path}: {error}") from None
    names = []
    for j in range(mj_model.njnt):
        if int(mj_model.jnt_type[j]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            raise KinematicsError(f"MuJoCo joint {j} has an unsupported type")
        names.append(mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, j))
    if list(mj_model.jnt_qposadr) != list(range(mj_model.njnt)):
        raise KinematicsError("MuJoCo model has joints with more than one coordinate")
    pin_indices = np.array([kinematics.q_index(name) for name in names], dtype=int)
    # Joint ranges follow the robot description (it may tighten the URDF's).
    for j, index in enumerate(pin_indices):
        mj_model.jnt_range[j] = (kinematics.lower[index], kinematics.upper[index])
        mj_model.jnt_limited[j] = 1
    return MujocoModel(mj_model, tuple(names), pin_indices)
