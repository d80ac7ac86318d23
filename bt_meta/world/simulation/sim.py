"""The pybullet world: a fixed-base Baxter, a table in front of it, and the paper's objects, headless by default.

Every pose is in the robot base frame (the URDF's ``base`` link, where Pinocchio's world is): the robot's base
is placed at the pybullet origin, so pybullet world coordinates *are* robot base coordinates.

Offers:

* :class:`Simulation` -- own physics client (``gui=True`` for a person at a screen), context manager; robot
  joints (teleport or drive targets and step), objects by name (spawn, move, remove, pose), grasp by fixed
  constraint or by the fingers' friction (per robot: ``gripper: grasp:``) and release, the magnetic attach rule
  (checked at every step, joins by fixed constraint), :meth:`Simulation.object_states` with AP/AN in the base
  frame, static obstacles (:meth:`Simulation.add_obstacle`); object parts are boxes, cylinders and meshes
* :class:`SimObjectState` -- ground truth of one object: pose, AP/AN (base and object frame), all features
* :class:`Table` -- where the table is (defaults: top 0.2 m below the base frame, front edge 0.45 m ahead)
* :class:`SimulationError` -- unknown object or link names, duplicate names, impossible requests

``BT_META_MERGE_FIXED_LINKS=1`` (or ``merge_fixed_links=True``) loads the robot with its fixed links merged into
the moving links they hang from (the Baxter: 19 links instead of 56), every link name still resolving to its
frame (:mod:`bt_meta.world.simulation.robot_links`): faster physics, but not bitwise the same dynamics, so it is
off by default (docs/benchmarks.md, "Episode cost").

Why the robot's visuals are its collision geometry by default (headless): the original DAE meshes take ~1.8 s
(CPU) to load and ~90 ms per 320x240 TinyRenderer frame; the collision shapes load in ~0.14 s and the eye-in-hand
frame costs ~16-20 ms. ``visuals="full"`` keeps the meshes; it is the default with ``gui=True``.
"""

from __future__ import annotations

import copy
import math
import os
import shutil
import socket
import tempfile
import xml.etree.ElementTree as ElementTree
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pybullet

from bt_meta.errors import BtMetaError
from bt_meta.model_cache import cached, clear_entry, file_signature
from bt_meta.world.robot.description import RobotDescription, load_robot
from bt_meta.world.simulation.objects import (
    COLOURS,
    AttachmentRelation,
    Box,
    Cylinder,
    Mesh,
    ObjectModel,
    Pose6,
    attachment_relation,
    matrix_to_pose,
)
from bt_meta.world.simulation.robot_links import merged_frames, read_joints, subtree

__all__ = ["SimObjectState", "Simulation", "SimulationError", "Table"]


class SimulationError(BtMetaError):
    """A request the simulation cannot carry out (unknown name, duplicate name, pose of the wrong length)."""


@dataclass(frozen=True)
class Table:
    """A static table slab. ``top_z`` is the height of its top surface in the robot base frame.

    The defaults put the top 0.20 m below the base frame, from x = 0.45 m (clear of the pedestal, which ends at
    x = 0.42 m) to 1.05 m, y from -0.65 to 0.45 m: the right gripper reaches it pointing straight down over
    x 0.45..0.75 m, y -0.55..0.15 m (checked by IK in tests/world/test_sim.py).
    """

    center_x: float = 0.75
    center_y: float = -0.10
    size_x: float = 0.60
    size_y: float = 1.10
    top_z: float = -0.20
    thickness: float = 0.04
    colour: tuple[float, float, float, float] = (0.93, 0.9, 0.83, 1.0)

    def shifted(self, offset: Sequence[float]) -> Table:
        """The same table moved by ``offset`` (x, y, z): the defaults are in the scene frame, a robot's
        ``workcell.scene_offset`` puts them in its base frame."""
        dx, dy, dz = (float(v) for v in offset)
        return replace(self, center_x=self.center_x + dx, center_y=self.center_y + dy, top_z=self.top_z + dz)

    @property
    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((x_min, x_max), (y_min, y_max)) of the top surface."""
        return (
            (self.center_x - self.size_x / 2.0, self.center_x + self.size_x / 2.0),
            (self.center_y - self.size_y / 2.0, self.center_y + self.size_y / 2.0),
        )


@dataclass(frozen=True)
class SimObjectState:
    """Ground truth of one object. ``ap``/``an`` are the primary feature in the robot base frame (what traces
    compare, paper section 7.2.1); ``ap_object``/``an_object`` the same feature in the object frame; ``features``
    maps every feature name to its (point, normal) in the base frame."""

    name: str
    type: str
    colour: str
    shape: str | None
    pose: Pose6
    ap: tuple[float, float, float]
    an: tuple[float, float, float]
    ap_object: tuple[float, float, float]
    an_object: tuple[float, float, float]
    features: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = field(default_factory=dict)
    held_by: str | None = None
    """The arm holding the object, if any."""
    attached_to: tuple[str, ...] = ()
    """Objects magnetically joined to this one."""

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "type": self.type,
            "colour": self.colour,
            "shape": self.shape,
            "pose": list(self.pose),
            "ap": list(self.ap),
            "an": list(self.an),
            "held_by": self.held_by,
            "attached_to": list(self.attached_to),
        }


@dataclass
class _Body:
    name: str
    model: ObjectModel
    body_id: int


@dataclass
class _Grasp:
    arm: str
    object_name: str
    constraint_id: int
    """The constraint holding the object (for a friction grasp, one no stronger than the fingers' friction)."""
    friction: bool = False
    """Held by the fingers' friction: released when they stop touching it or it slides in them."""
    relative: np.ndarray | None = None
    """Friction grasps: the object's pose in the end-effector frame when the fingers closed."""
    lost: int = 0
    """Friction grasps: consecutive checks the fingers did not both touch the object."""


_FINGER_FRICTION = 1.0
"""Lateral friction of the finger links of a friction gripper (rubber pads)."""
_PRESHAPE_MARGIN = 0.006
"""Each side (m): how much wider than the part the fingers open before closing on it."""
_MAX_COMPOUND = 16
"""pybullet's MAX_COMPOUND_COLLISION_SHAPES: shapes one createCollisionShapeArray keeps."""
_CLOSE_SPEED = 0.1
"""m/s: how fast a friction gripper's fingers close (the Franka hand's limit is 0.2 in its URDF)."""
_FIT_MARGIN = 0.002
"""Each side (m): a part fits the fingers when it is this much narrower than their opening."""
_CLOSE_STEPS = 120
"""Physics steps (0.5 s) a friction grasp lets the fingers close before judging whether they hold the part."""
_LOST_AFTER = 2
"""A friction grasp is lost after this many consecutive step() calls without both fingers touching the part."""
_HOLD_TOUCH = 0.001
"""m: a finger of a friction grasp this near the part it holds still touches it. Bullet reports no contact for a
pad resting on a flat face under a tenth of a millimetre of squeeze at some steps: a housing held by its 7 cm flange
in the Panda's fingers was let go on the way down, held fast (a part that slips out leaves by centimetres)."""
_COUPLING_ERP = 0.8
"""How hard the coupling of two fingers pulls them back to mirror images each physics step (pybullet's gear keeps
their velocities equal only loosely; at 0.1 the pair crept sideways on a part it squeezed -- 7 mm apart on the
letters' blocks, the part 2 mm off their middle -- and a finger stopped by an off-centre part let the other run on
to its closed limit)."""
_COUPLING_FORCE = 10.0
"""The coupling's strength: this many times one finger's force."""
_HOLD_SQUEEZE = 0.0005
"""m per finger: once a friction grasp holds the part, the fingers are held this far inside where they closed on
it; driven on to their closed limit they sank into Bullet's soft contacts under the sustained squeeze, unevenly,
and the pair crept sideways with the part (the squeeze itself is the grasp constraint's strength)."""


def _tuple3(v: Iterable[float]) -> tuple[float, float, float]:
    a, b, c = (float(x) for x in v)
    return (a, b, c)


def _merge_by_default() -> bool:
    """``BT_META_MERGE_FIXED_LINKS=1``: load the robot with its fixed links merged (faster physics, see
    :mod:`bt_meta.world.simulation.robot_links`). Off by default: the merged assembly is the same rigid body, but
    its dynamics differ numerically, and a few friction-grasped insertions (housing) end differently."""
    return os.environ.get("BT_META_MERGE_FIXED_LINKS", "0") not in ("", "0")


_URDF_FOLDER: tempfile.TemporaryDirectory[str] | None = None
_URDF_PREFIX = "bt_meta_sim_"


def _folder_prefix(pid: int) -> str:
    return f"{_URDF_PREFIX}{socket.gethostname()}_{pid}_"


def _remove_orphaned_urdf_folders(root: Path) -> list[Path]:
    """Remove the URDF folders of this host's bt-meta processes that are gone (a SIGKILLed campaign worker cannot
    remove its own). A folder is removed only when its name carries this host and the PID of no living process."""
    removed = []
    mine = f"{_URDF_PREFIX}{socket.gethostname()}_"
    for folder in root.glob(f"{_URDF_PREFIX}*"):
        rest = folder.name[len(mine):] if folder.name.startswith(mine) else None
        pid_text = None if rest is None else rest.split("_", 1)[0]
        if not folder.is_dir() or pid_text is None or not pid_text.isdigit():
            continue
        try:
            os.kill(int(pid_text), 0)
        except ProcessLookupError:
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
        except PermissionError:  # alive, another user's
            continue
    return removed


def _robot_urdf_file(robot: RobotDescription, visuals: str) -> Path:
    """The URDF pybullet loads, written once per process (:mod:`bt_meta.model_cache`) into a folder
    removed when the process ends: a worker serving many episodes does not rewrite it for each world."""
    global _URDF_FOLDER
    if _URDF_FOLDER is None:
        _remove_orphaned_urdf_folders(Path(tempfile.gettempdir()))
        _URDF_FOLDER = tempfile.TemporaryDirectory(prefix=_folder_prefix(os.getpid()))
    folder = Path(_URDF_FOLDER.name)
    key = ("pybullet urdf", visuals, file_signature(robot.urdf_path), tuple(str(p) for p in robot.package_dirs))
    write = _light_urdf if visuals == "light" else _full_urdf

    def written() -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        return write(robot, Path(tempfile.mkdtemp(dir=folder)))

    path = cached(key, written)
    if not path.is_file():  # removed under us (a /tmp cleaner): write it again
        clear_entry(key)
        path = cached(key, written)
    return path


def _light_urdf(robot: RobotDescription, directory: Path) -> Path:
    """A copy of the robot's URDF whose visuals are its collision geometry and whose mesh paths are absolute."""
    tree = ElementTree.parse(robot.urdf_path)
    root = tree.getroot()
    for link in root.findall("link"):
        visuals = link.findall("visual")
        material = next((v.find("material") for v in visuals if v.find("material") is not None), None)
        for v in visuals:
            link.remove(v)
        for collision in link.findall("collision"):
            geometry = collision.find("geometry")
            if geometry is None:
                continue
            visual = ElementTree.SubElement(link, "visual")
            origin = collision.find("origin")
            if origin is not None:
                visual.append(copy.deepcopy(origin))
            visual.append(copy.deepcopy(geometry))
            if material is not None:
                visual.append(copy.deepcopy(material))
    _absolute_meshes(root, robot)
    out = directory / "robot_light.urdf"
    tree.write(out)
    return out


def _full_urdf(robot: RobotDescription, directory: Path) -> Path:
    tree = ElementTree.parse(robot.urdf_path)
    _absolute_meshes(tree.getroot(), robot)
    out = directory / "robot_full.urdf"
    tree.write(out)
    return out


def _absolute_meshes(root: ElementTree.Element, robot: RobotDescription) -> None:
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        if filename.startswith("package://"):
            relative = filename[len("package://") :]
            for base in robot.package_dirs:
                if (Path(base) / relative).is_file():
                    mesh.set("filename", str(Path(base) / relative))
                    break
            else:
                raise SimulationError(f"mesh {filename} is not under any package dir {robot.package_dirs}")


class Simulation:
    """A pybullet world with the Baxter, a table and named objects.

    Use as a context manager (or call :meth:`close`): it owns its physics client and never touches pybullet's
    global default client. Stepping is deterministic: the same calls give the same poses; ``seed`` feeds
    :attr:`rng`, the generator every random draw about this world (scene jitter) must use.
    """

    def __init__(
        self,
        *,
        gui: bool = False,
        seed: int = 0,
        robot: RobotDescription | None = None,
        table: Table | None = None,
        time_step: float = 1.0 / 240.0,
        visuals: str | None = None,
        attach_position_tolerance: float = 0.01,
        attach_angle_tolerance: float = math.radians(15.0),
        merge_fixed_links: bool | None = None,
    ) -> None:
        visuals = visuals or ("full" if gui else "light")  # a person at a screen gets the real meshes
        if visuals not in ("light", "full"):
            raise SimulationError(f"visuals must be 'light' or 'full', not {visuals!r}")
        self.robot = robot or load_robot()
        self.table = table or Table().shifted(self.robot.scene_offset)
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.time_step = time_step
        self.attach_position_tolerance = attach_position_tolerance
        self.attach_angle_tolerance = attach_angle_tolerance
        self.steps = 0
        self.merge_fixed_links = merge_fixed_links if merge_fixed_links is not None else _merge_by_default()
        self.client = pybullet.connect(pybullet.GUI if gui else pybullet.DIRECT)
        if self.client < 0:
            raise SimulationError("pybullet could not connect (is another GUI window open?)")
        self._closed = False
        try:
            self._setup(visuals)
            if gui:
                pybullet.resetDebugVisualizerCamera(
                    1.8,
                    60.0,
                    -35.0,
                    [self.table.center_x - 0.1, self.table.center_y, self.table.top_z],
                    physicsClientId=self.client,
                )
        except BaseException:
            self.close()
            raise

    # -- set-up ----------------------------------------------------------------------------------------------

    def _setup(self, visuals: str) -> None:
        c = self.client
        pybullet.resetSimulation(physicsClientId=c)
        pybullet.setPhysicsEngineParameter(
            fixedTimeStep=self.time_step, deterministicOverlappingPairs=1, physicsClientId=c
        )
        pybullet.setGravity(0.0, 0.0, -9.81, physicsClientId=c)
        urdf = _robot_urdf_file(self.robot, visuals)
        # Fixed links merged into the moving link they hang from (robot_links): 19 bodies to integrate, not 56.
        self.robot_id = pybullet.loadURDF(
            str(urdf), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], useFixedBase=True,
            flags=pybullet.URDF_MERGE_FIXED_LINKS if self.merge_fixed_links else 0, physicsClientId=c
        )
        self._joint_index: dict[str, int] = {}
        self._link_index: dict[str, int] = {pybullet.getBodyInfo(self.robot_id, physicsClientId=c)[0].decode(): -1}
        self._limits: dict[str, tuple[float, float]] = {}
        for j in range(pybullet.getNumJoints(self.robot_id, physicsClientId=c)):
            info = pybullet.getJointInfo(self.robot_id, j, physicsClientId=c)
            self._link_index[info[12].decode()] = j
            if info[2] != pybullet.JOINT_FIXED:
                name = info[1].decode()
                self._joint_index[name] = j
                self._limits[name] = (info[8], info[9])
        self._link_name: dict[int, str] = {index: name for name, index in self._link_index.items()}
        """pybullet link index -> the link's name in pybullet (a merged link's survivor)."""
        self._urdf_joints = read_joints(self.robot.urdf_path)
        self._link_offset: dict[str, np.ndarray] = {}
        """A merged link's fixed pose in the URDF frame of the link it was merged into."""
        for name, (kept, offset) in merged_frames(self._urdf_joints, self._link_index).items():
            self._link_index[name] = self._link_index[kept]
            self._link_offset[name] = offset
        dynamics = pybullet.getDynamicsInfo(self.robot_id, -1, physicsClientId=c)
        # pybullet reports the base's pose at its centre of mass, which merging moves: keep the inverse of that
        # inertial frame to recover the URDF base frame.
        self._base_from_inertial = np.linalg.inv(_transform(dynamics[3], dynamics[4]))
        self.movable_joints: tuple[str, ...] = tuple(self._joint_index)
        self._targets: dict[str, float] = {}
        self._bodies: dict[str, _Body] = {}
        self._obstacles: dict[str, _Body] = {}
        self._by_id: dict[int, str] = {}
        self._grasps: dict[str, _Grasp] = {}
        self._joins: dict[frozenset[str], int] = {}
        self._pending_collision: list[tuple[str, str]] = []
        self._finger_links: dict[str, tuple[int, ...]] = {}
        self._forces: dict[str, float] = {}
        """Motor force (N) of joints that do not use the default 500 (a friction gripper's fingers)."""
        self.set_joint_positions(self.robot.home)
        self.table_id = self._make_table()
        self._hand_links: dict[str, tuple[int, ...]] = {
            arm: self._hand_link_indices(arm) for arm in self.robot.arms
        }
        for arm, description in self.robot.arms.items():
            gripper = description.gripper
            if gripper is None or gripper.grasp != "friction":
                continue
            self._finger_links[arm] = tuple(self._joint_index[j] for j in gripper.joints)
            for joint in gripper.joints:
                self._forces[joint] = gripper.force
            for link in self._finger_links[arm]:
                pybullet.changeDynamics(self.robot_id, link, lateralFriction=_FINGER_FRICTION,
                                        physicsClientId=self.client)
            if len(gripper.joints) == 2:
                # The fingers move together, as the hand's mechanism couples them: two independent motors that
                # both push at full force give a held part no lateral stiffness, it slides with the fingers.
                first, second = self._finger_links[arm]
                ratio = -1.0 if gripper.open[0] * gripper.open[1] > 0 else 1.0
                gear = pybullet.createConstraint(self.robot_id, first, self.robot_id, second, pybullet.JOINT_GEAR,
                                                 [1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0],
                                                 physicsClientId=self.client)
                pybullet.changeConstraint(gear, gearRatio=ratio, erp=_COUPLING_ERP,
                                          maxForce=_COUPLING_FORCE * gripper.force, physicsClientId=self.client)

    def _hand_root(self, arm: str) -> str:
        """The wrist-side link of the hand (URDF name): everything below it may touch a held object."""
        joints = self._urdf_joints
        wrist = next((j.child for j in joints.values() if j.name == self.robot.arm(arm).joints[-1]), None)
        link = self.robot.arm(arm).end_effector
        # Walk up from the gripper frame to the link whose parent moves with the last arm joint.
        while link in joints and joints[link].parent != wrist:
            link = joints[link].parent
        return link

    def _hand_link_indices(self, arm: str) -> tuple[int, ...]:
        """The pybullet links of the hand: with fixed links merged the hand's base lives on the wrist link, so
        the wrist's own shapes count as the hand's."""
        names = subtree(self._urdf_joints, self._hand_root(arm))
        return tuple(sorted({self._link_index[n] for n in names if n in self._link_index}))

    def _make_table(self) -> int:
        t, c = self.table, self.client
        half = [t.size_x / 2.0, t.size_y / 2.0, t.thickness / 2.0]
        col = pybullet.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half, physicsClientId=c)
        vis = pybullet.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=t.colour, physicsClientId=c)
        body = pybullet.createMultiBody(
            0.0, col, vis, [t.center_x, t.center_y, t.top_z - t.thickness / 2.0], physicsClientId=c
        )
        pybullet.changeDynamics(body, -1, lateralFriction=0.8, physicsClientId=c)
        return body

    # -- lifetime --------------------------------------------------------------------------------------------

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            pybullet.disconnect(physicsClientId=self.client)

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- robot -----------------------------------------------------------------------------------------------

    def link_index(self, name: str) -> int:
        try:
            return self._link_index[name]
        except KeyError:
            raise SimulationError(f"the robot has no link {name!r}") from None

    def joint_index(self, name: str) -> int:
        try:
            return self._joint_index[name]
        except KeyError:
            raise SimulationError(f"the robot has no movable joint {name!r}") from None

    def joint_limits(self, name: str) -> tuple[float, float]:
        self.joint_index(name)
        return self._limits[name]

    def joint_positions(self, names: Sequence[str] | None = None) -> dict[str, float]:
        """Current joint values by name (all movable joints unless ``names``)."""
        names = self.movable_joints if names is None else names
        idx = [self.joint_index(n) for n in names]
        states = pybullet.getJointStates(self.robot_id, idx, physicsClientId=self.client)
        return {n: float(s[0]) for n, s in zip(names, states, strict=True)}

    def set_joint_positions(self, q: Mapping[str, float]) -> None:
        """Teleport joints (zero velocity) and make the values the motors' targets, so they stay.

        Held objects (and what is magnetically joined to them) are carried along, so the grasp constraint does
        not yank them across the table on the next step."""
        carried: list[tuple[str, str, np.ndarray]] = []  # (object, arm, pose in the end-effector frame)
        for arm, grasp in self._grasps.items():
            end = self.link_transform(self.robot.arm(arm).end_effector)
            for name in (grasp.object_name, *self._joined_to(grasp.object_name)):
                carried.append((name, arm, np.linalg.inv(end) @ self.object_transform(name)))
        for name, value in q.items():
            pybullet.resetJointState(
                self.robot_id, self.joint_index(name), float(value), 0.0, physicsClientId=self.client
            )
        self.set_joint_targets(q)
        for name, arm, relative in carried:
            pose = self.link_transform(self.robot.arm(arm).end_effector) @ relative
            self.move_object(name, matrix_to_pose(pose))

    def home(self) -> None:
        """Let go of everything and put the robot in its home pose (the description's)."""
        for arm in list(self._grasps):
            self.release(arm)
        self.set_joint_positions(self.robot.home)

    def _joined_to(self, name: str) -> list[str]:
        """Every object rigidly joined to ``name`` through magnetic joins (transitively)."""
        seen, frontier = {name}, [name]
        while frontier:
            current = frontier.pop()
            for pair in self._joins:
                if current in pair:
                    for other in pair:
                        if other not in seen:
                            seen.add(other)
                            frontier.append(other)
        seen.discard(name)
        return sorted(seen)

    def set_joint_targets(self, q: Mapping[str, float], max_velocity: float | None = None) -> None:
        """Position targets the motors drive to while :meth:`step` runs (other joints keep their targets)."""
        for name, value in q.items():
            self.joint_index(name)
            self._targets[name] = float(value)
        names = list(self._targets)
        idx = [self._joint_index[n] for n in names]
        pybullet.setJointMotorControlArray(
            self.robot_id,
            idx,
            pybullet.POSITION_CONTROL,
            targetPositions=[self._targets[n] for n in names],
            forces=[self._forces.get(n, 500.0) for n in names],
            physicsClientId=self.client,
        )
        if max_velocity is not None:
            for name, value in q.items():
                pybullet.setJointMotorControl2(
                    self.robot_id,
                    self._joint_index[name],
                    pybullet.POSITION_CONTROL,
                    targetPosition=float(value),
                    force=self._forces.get(name, 500.0),
                    maxVelocity=max_velocity,
                    physicsClientId=self.client,
                )

    def joint_targets(self) -> dict[str, float]:
        return dict(self._targets)

    def target_error(self, names: Sequence[str] | None = None) -> float:
        """Largest |target - position| over the named joints (all driven joints by default): has a move arrived?"""
        names = list(self._targets) if names is None else list(names)
        now = self.joint_positions(names)
        return max((abs(self._targets.get(n, now[n]) - now[n]) for n in names), default=0.0)

    def set_gripper(self, arm: str, state: str) -> None:
        """Drive the fingers ``"open"`` or ``"closed"`` (the robot description's values). Cosmetic for holding:
        a grasp is a constraint (see :meth:`grasp`), but the fingers show what the gripper does."""
        gripper = self.robot.arm(arm).gripper
        if gripper is None:
            raise SimulationError(f"arm {arm!r} has no gripper")
        if state not in ("open", "closed"):
            raise SimulationError(f"a gripper is 'open' or 'closed', not {state!r}")
        values = gripper.open if state == "open" else gripper.closed
        self.set_joint_targets(dict(zip(gripper.joints, values, strict=True)))

    def link_transform(self, link: str) -> np.ndarray:
        """4x4 pose of a robot link's URDF frame in the base frame."""
        index = self.link_index(link)
        if index == -1:
            pos, quat = pybullet.getBasePositionAndOrientation(self.robot_id, physicsClientId=self.client)
            frame = _transform(pos, quat) @ self._base_from_inertial
        else:
            state = pybullet.getLinkState(
                self.robot_id, index, computeForwardKinematics=True, physicsClientId=self.client
            )
            frame = _transform(state[4], state[5])
        offset = self._link_offset.get(link)
        return frame if offset is None else frame @ offset

    def link_pose(self, link: str) -> Pose6:
        return matrix_to_pose(self.link_transform(link))

    def gripper_pose(self, arm: str | None = None) -> Pose6:
        """Pose of the arm's end-effector frame (between the fingertips, z = approach)."""
        arm = arm or self.robot.default_arm
        return self.link_pose(self.robot.arm(arm).end_effector)

    def step(self, n: int = 1) -> None:
        """Advance physics ``n`` fixed time steps, checking the magnetic attach rule after each."""
        pairs = self._magnet_pairs()
        for _ in range(n):
            pybullet.stepSimulation(physicsClientId=self.client)
            self.steps += 1
            for active, reference in pairs:
                if frozenset((active, reference)) not in self._joins:
                    self.try_attach(active, reference)
        if self._pending_collision:
            self._restore_collisions()
        if self._finger_links:
            self._check_friction_grasps()

    def settle(self, steps: int = 240) -> None:
        """Let objects come to rest (one second of simulated time by default)."""
        self.step(steps)

    # -- objects ---------------------------------------------------------------------------------------------

    def spawn(self, name: str, model: ObjectModel, pose: Sequence[float], *, on_table: bool = False) -> int:
        """Create an object at ``pose`` (x, y, z, roll, pitch, yaw); ``on_table`` replaces z by the height at
        which the geometry, so turned, rests on the table top (loose objects 0.5 mm higher: they start out of contact
        and drop)."""
        if name in self._bodies or name in self._obstacles:
            raise SimulationError(f"an object named {name!r} already exists")
        pose = self._checked_pose(pose, name)
        if on_table:
            pose = self.resting_pose(model, pose)
        body = self._create_body(model, pose)
        self._bodies[name] = _Body(name, model, body)
        self._by_id[body] = name
        return body

    def add_obstacle(self, name: str, model: ObjectModel, pose: Sequence[float]) -> int:
        """A static obstacle (see :mod:`~bt_meta.world.simulation.obstacles`) at ``pose``: a body the cameras
        see and the physics collides with, but not an object of the task (not in :meth:`object_names`)."""
        if name in self._bodies or name in self._obstacles:
            raise SimulationError(f"an object named {name!r} already exists")
        if model.mass != 0.0:
            raise SimulationError(f"obstacle {name!r} must be static (mass 0), not {model.mass} kg")
        pose = self._checked_pose(pose, name)
        body = self._create_body(model, pose)
        self._obstacles[name] = _Body(name, model, body)
        return body

    def obstacles(self) -> dict[str, tuple[ObjectModel, np.ndarray]]:
        """Every static obstacle: name -> (model, 4x4 pose in the base frame)."""
        out = {}
        for name, body in self._obstacles.items():
            pos, quat = pybullet.getBasePositionAndOrientation(body.body_id, physicsClientId=self.client)
            out[name] = (body.model, _transform(pos, quat))
        return out

    def obstacle_name_of(self, body_id: int) -> str | None:
        return next((name for name, body in self._obstacles.items() if body.body_id == body_id), None)

    def _create_body(self, model: ObjectModel, pose: Sequence[float]) -> int:
        """A pybullet body of the model's parts. pybullet takes at most 16 shapes per compound
        (MAX_COMPOUND_COLLISION_SHAPES) and silently drops the rest: a model with more parts (the housing's 24
        tube segments) is a base of 16 and links of up to 16 more each, fixed to it at the object frame."""
        c = self.client
        chunks = [model.parts[k : k + _MAX_COMPOUND] for k in range(0, len(model.parts), _MAX_COMPOUND)]
        shapes = [self._shape_arrays(chunk) for chunk in chunks]
        masses = [model.mass * len(chunk) / len(model.parts) for chunk in chunks]
        extra = len(chunks) - 1
        body = pybullet.createMultiBody(
            masses[0],
            shapes[0][0],
            shapes[0][1],
            list(pose[:3]),
            list(pybullet.getQuaternionFromEuler(pose[3:])),
            linkMasses=masses[1:],
            linkCollisionShapeIndices=[col for col, _ in shapes[1:]],
            linkVisualShapeIndices=[vis for _, vis in shapes[1:]],
            linkPositions=[[0.0, 0.0, 0.0]] * extra,
            linkOrientations=[[0.0, 0.0, 0.0, 1.0]] * extra,
            linkInertialFramePositions=[[0.0, 0.0, 0.0]] * extra,
            linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * extra,
            linkParentIndices=[0] * extra,
            linkJointTypes=[pybullet.JOINT_FIXED] * extra,
            linkJointAxis=[[0.0, 0.0, 1.0]] * extra,
            physicsClientId=c,
        )
        for link in range(-1, extra):
            # createVisualShapeArray has no per-shape colour (and crashes when given one): colour the whole body.
            pybullet.changeVisualShape(body, link, rgbaColor=list(COLOURS[model.colour]), physicsClientId=c)
            pybullet.changeDynamics(
                body, link, lateralFriction=model.lateral_friction, spinningFriction=model.spinning_friction,
                rollingFriction=model.rolling_friction, physicsClientId=c
            )
        return body

    def _shape_arrays(self, parts: Sequence[Any]) -> tuple[int, int]:
        """(collision, visual) shape arrays of up to 16 parts."""
        c = self.client
        kinds, halves, radii, lengths, positions, orientations = [], [], [], [], [], []
        files: list[str] = []
        scales: list[list[float]] = []
        for part in parts:
            files.append(part.file if isinstance(part, Mesh) else "")
            scales.append(list(part.scale) if isinstance(part, Mesh) else [1.0, 1.0, 1.0])
            positions.append(list(part.position))
            orientations.append(list(pybullet.getQuaternionFromEuler(part.rpy)))
            if isinstance(part, Box):
                kinds.append(pybullet.GEOM_BOX)
                halves.append([v / 2.0 for v in part.size])
                radii.append(0.0)
                lengths.append(0.0)
            elif isinstance(part, Cylinder):
                kinds.append(pybullet.GEOM_CYLINDER)
                halves.append([0.0, 0.0, 0.0])
                radii.append(part.radius)
                lengths.append(part.length)
            elif isinstance(part, Mesh):
                kinds.append(pybullet.GEOM_MESH)
                halves.append([0.0, 0.0, 0.0])
                radii.append(0.0)
                lengths.append(0.0)
            else:  # pragma: no cover - ObjectModel only holds these
                raise SimulationError(f"unknown part {part!r}")
        arrays = {"radii": radii, "halfExtents": halves, "lengths": lengths, "fileNames": files,
                  "meshScales": scales}
        col = pybullet.createCollisionShapeArray(kinds, collisionFramePositions=positions,
                                                 collisionFrameOrientations=orientations, physicsClientId=c,
                                                 **arrays)
        vis = pybullet.createVisualShapeArray(kinds, visualFramePositions=positions,
                                              visualFrameOrientations=orientations, physicsClientId=c, **arrays)
        return col, vis

    def resting_pose(self, model: ObjectModel, pose: Sequence[float]) -> Pose6:
        """``pose`` with z set so the model, turned by its roll and pitch, rests on the table top."""
        pose = self._checked_pose(pose, model.type)
        gap = 0.0 if model.mass == 0.0 else 0.0005  # a static body never falls: put it exactly on the table
        z = self.table.top_z + model.lowest_z(pose[3], pose[4]) + gap
        return (pose[0], pose[1], z, pose[3], pose[4], pose[5])

    def remove(self, name: str) -> None:
        body = self._body(name)
        for arm, grasp in list(self._grasps.items()):
            if grasp.object_name == name:
                self.release(arm)
        for pair in [p for p in self._joins if name in p]:
            a, b = tuple(pair)
            self.detach(a, b)
        # pybullet reuses body ids and keeps collision filter pairs: switch every pair back on before the id goes,
        # or the next object with this id would pass through the hand.
        for arm, links in self._hand_links.items():
            if (arm, name) in self._pending_collision:
                self._hand_collisions(body.body_id, links, True)
        self._pending_collision = [p for p in self._pending_collision if p[1] != name]
        pybullet.removeBody(body.body_id, physicsClientId=self.client)
        del self._bodies[name]
        del self._by_id[body.body_id]

    def clear_objects(self) -> None:
        """Remove every object and obstacle (an empty table, to build another scene on)."""
        for name in list(self._bodies):
            self.remove(name)
        for body in self._obstacles.values():
            pybullet.removeBody(body.body_id, physicsClientId=self.client)
        self._obstacles.clear()

    def move_object(self, name: str, pose: Sequence[float]) -> None:
        """Teleport an object (velocity zeroed)."""
        body = self._body(name)
        pose = self._checked_pose(pose, name)
        pybullet.resetBasePositionAndOrientation(
            body.body_id, list(pose[:3]), pybullet.getQuaternionFromEuler(pose[3:]), physicsClientId=self.client
        )
        pybullet.resetBaseVelocity(body.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=self.client)

    def object_names(self) -> tuple[str, ...]:
        return tuple(self._bodies)

    def object_model(self, name: str) -> ObjectModel:
        return self._body(name).model

    def body_id(self, name: str) -> int:
        return self._body(name).body_id

    def box_clearances(self, size: Sequence[float], pose: np.ndarray, names: Iterable[str],
                       within: float) -> dict[str, float]:
        """Ground-truth distance (m, negative: overlap) from a box of full ``size`` at the 4x4 ``pose`` to each named
        object (or static obstacle) closer than ``within``: would something put there touch them? The box is a
        probe, never simulated (made and removed here, no step in between)."""
        half = [float(v) / 2.0 for v in size]
        shape = pybullet.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half, physicsClientId=self.client)
        pose = np.asarray(pose, dtype=float)
        probe = pybullet.createMultiBody(0.0, shape, -1, pose[:3, 3].tolist(), _quat(pose[:3, :3]),
                                         physicsClientId=self.client)
        try:
            out = {}
            for name in names:
                body = self._obstacles[name] if name in self._obstacles else self._body(name)
                points = pybullet.getClosestPoints(probe, body.body_id, float(within), physicsClientId=self.client)
                if points:
                    out[name] = min(float(point[8]) for point in points)
            return out
        finally:
            pybullet.removeBody(probe, physicsClientId=self.client)  # its shape goes with it (pybullet frees it)

    def object_name_of(self, body_id: int) -> str | None:
        """The object name of a pybullet body id (e.g. from a segmentation mask), ``None`` for robot/table."""
        return self._by_id.get(body_id)

    def object_transform(self, name: str) -> np.ndarray:
        pos, quat = pybullet.getBasePositionAndOrientation(self._body(name).body_id, physicsClientId=self.client)
        return _transform(pos, quat)

    def object_pose(self, name: str) -> Pose6:
        return matrix_to_pose(self.object_transform(name))

    def feature(self, name: str, feature: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(point, normal) of an object's attachment feature (primary if ``None``) in the base frame."""
        model = self._body(name).model
        f = model.feature(feature)
        t = self.object_transform(name)
        return t[:3, :3] @ np.array(f.point) + t[:3, 3], t[:3, :3] @ np.array(f.normal)

    def object_state(self, name: str) -> SimObjectState:
        model = self._body(name).model
        t = self.object_transform(name)
        rot, pos = t[:3, :3], t[:3, 3]
        features = {
            f.name: (_tuple3(rot @ np.array(f.point) + pos), _tuple3(rot @ np.array(f.normal))) for f in model.features
        }
        primary = model.feature()
        held = next((g.arm for g in self._grasps.values() if g.object_name == name), None)
        joined = tuple(sorted(other for pair in self._joins if name in pair for other in pair if other != name))
        return SimObjectState(
            name=name,
            type=model.type,
            colour=model.colour,
            shape=model.shape,
            pose=matrix_to_pose(t),
            ap=features[primary.name][0],
            an=features[primary.name][1],
            ap_object=primary.point,
            an_object=primary.normal,
            features=features,
            held_by=held,
            attached_to=joined,
        )

    def object_states(self) -> dict[str, SimObjectState]:
        """Every object's ground truth by name (robot base frame)."""
        return {name: self.object_state(name) for name in self._bodies}

    def contacts(self, name: str) -> set[str]:
        """Names of what an object touches: other objects, ``"table"``, ``"robot"``."""
        body = self._body(name).body_id
        out: set[str] = set()
        for contact in pybullet.getContactPoints(bodyA=body, physicsClientId=self.client):
            other = contact[2]
            if other == self.table_id:
                out.add("table")
            elif other == self.robot_id:
                out.add("robot")
            elif other in self._by_id:
                out.add(self._by_id[other])
            elif (obstacle := self.obstacle_name_of(other)) is not None:
                out.add(obstacle)
        return out

    # -- grasp -----------------------------------------------------------------------------------------------

    def grasp(self, name: str, arm: str | None = None, *, max_distance: float = 0.03) -> bool:
        """Hold ``name`` in the arm's gripper: by friction when the gripper's description says ``grasp: friction``
        and the part fits between its fingers (:meth:`fits`), else by a fixed constraint at the current relative
        pose.

        The Baxter's gripper cannot open wide enough for a Mega Blok (4.62 cm < 6.1 cm), so its grasp is this
        constraint, with collisions between the hand and the object off. A friction grasp closes the fingers
        (physics steps, up to 0.5 s) and holds the part only if both fingers then touch it, by a constraint no
        stronger than their friction (pads x part friction x the fingers' squeeze); afterwards the part stays
        held while both fingers touch it (checked at every :meth:`step`; a part that slid 5 mm in them, pressed
        onto a support, is held where it slid to): a part too heavy or too slippery for the fingers slips out, and
        :meth:`held` says so. Returns False (and holds nothing)
        when the gripper frame is farther than ``max_distance`` from the object's surface, the arm already holds
        something, or the fingers closed without holding it -- a physical failure the skill reports.
        """
        arm = arm or self.robot.default_arm
        body = self._body(name)
        if arm in self._grasps:
            return False
        if any(g.object_name == name for g in self._grasps.values()):
            return False
        end = self.link_index(self.robot.arm(arm).end_effector)
        if self._distance_to_gripper(body.body_id, self.robot.arm(arm).end_effector) > max_distance:
            return False
        if self.grasps_by_friction(name, arm):
            return self._close_on(name, arm)
        c = self.client
        link_state = pybullet.getLinkState(self.robot_id, end, computeForwardKinematics=True, physicsClientId=c)
        parent = _transform(link_state[0], link_state[1])  # constraint frames are relative to the link's COM frame
        child = self.object_transform(name)
        rel = np.linalg.inv(parent) @ child
        self._hand_collisions(body.body_id, self._hand_links[arm], False)
        self._pending_collision = [p for p in self._pending_collision if p[1] != name]
        cid = _fix(self.robot_id, end, body.body_id, rel, c)
        self._grasps[arm] = _Grasp(arm, name, cid, relative=rel)
        return True

    def grasps_by_friction(self, name: str, arm: str | None = None) -> bool:
        """Whether a grasp of ``name`` by ``arm`` would be by the fingers' friction (the gripper is described
        ``grasp: friction`` and the part, as it is turned now, fits between the open fingers)."""
        arm = arm or self.robot.default_arm
        return arm in self._finger_links and self.fits(name, arm)

    def closing_axis(self, arm: str | None = None) -> np.ndarray:
        """Unit vector (base frame) along which the arm's first finger moves when the gripper opens."""
        arm = arm or self.robot.default_arm
        gripper = self.robot.arm(arm).gripper
        if gripper is None:
            raise SimulationError(f"arm {arm!r} has no gripper")
        if gripper.closing_axis is not None:  # fingers that do not move: the description says across what
            world = self.link_transform(self.robot.arm(arm).end_effector)[:3, :3] @ np.asarray(gripper.closing_axis)
            return world / max(float(np.linalg.norm(world)), 1e-12)
        joint = self._joint_index[gripper.joints[0]]
        axis = np.array(pybullet.getJointInfo(self.robot_id, joint, physicsClientId=self.client)[13], dtype=float)
        state = pybullet.getLinkState(self.robot_id, joint, computeForwardKinematics=True,
                                      physicsClientId=self.client)
        world = _transform(state[4], state[5])[:3, :3] @ axis
        return world / max(float(np.linalg.norm(world)), 1e-12)

    def width_across(self, name: str, arm: str | None = None) -> float:
        """The part's extent (m) along the arm's finger closing axis, as it is turned now."""
        arm = arm or self.robot.default_arm
        t = self.object_transform(name)
        points = self._body(name).model.points() @ t[:3, :3].T
        along = points @ self.closing_axis(arm)
        return float(along.max() - along.min())

    def fits(self, name: str, arm: str | None = None) -> bool:
        """Whether the part fits between the arm's open fingers."""
        arm = arm or self.robot.default_arm
        gripper = self.robot.arm(arm).gripper
        return gripper is not None and self.width_across(name, arm) <= gripper.opening - 2.0 * _FIT_MARGIN

    def preshape(self, arm: str, name: str) -> None:
        """Open the fingers of a friction gripper just wider than ``name`` (a few millimetres each side), so
        they go down around it without touching what stands next to it. Nothing for other grippers."""
        if not self.grasps_by_friction(name, arm):
            return
        self._open_to(arm, self.width_across(name, arm) + 2.0 * _PRESHAPE_MARGIN)

    def _open_to(self, arm: str, width: float) -> None:
        gripper = self.robot.arm(arm).gripper
        assert gripper is not None
        fraction = min(1.0, max(0.0, width / gripper.opening))
        values = [c + fraction * (o - c) for o, c in zip(gripper.open, gripper.closed, strict=True)]
        self.set_joint_targets(dict(zip(gripper.joints, values, strict=True)))

    def touching_fingers(self, name: str, arm: str | None = None, within: float = 0.0) -> int:
        """How many of the arm's fingers touch ``name`` (friction grippers; 0 for others); with ``within`` > 0,
        how many are at most that far (m) from it."""
        arm = arm or self.robot.default_arm
        body = self._body(name).body_id
        if within > 0.0:
            return sum(1 for link in self._finger_links.get(arm, ())
                       if pybullet.getClosestPoints(self.robot_id, body, within, linkIndexA=link,
                                                    physicsClientId=self.client))
        return sum(
            1
            for link in self._finger_links.get(arm, ())
            if pybullet.getContactPoints(self.robot_id, body, linkIndexA=link, physicsClientId=self.client)
        )

    def _close_on(self, name: str, arm: str) -> bool:
        gripper = self.robot.arm(arm).gripper
        assert gripper is not None
        # at the hand's speed: a 15 g finger driven by its full force alone crosses a 2.6 cm wall in one physics
        # step (the housing's flange), closing inside it
        self.set_joint_targets(dict(zip(gripper.joints, gripper.closed, strict=True)), max_velocity=_CLOSE_SPEED)
        fingers = len(self._finger_links[arm])
        for _ in range(_CLOSE_STEPS // 8):
            self.step(8)
            if self.touching_fingers(name, arm) == fingers:
                moving = pybullet.getJointStates(self.robot_id, list(self._finger_links[arm]),
                                                 physicsClientId=self.client)
                if all(abs(state[1]) < 1e-3 for state in moving):
                    break
        if self.touching_fingers(name, arm) < fingers:
            self.preshape(arm, name)
            return False
        # What the fingers can hold: Coulomb friction at both pads, mu (pads x part, Bullet's product) times the
        # squeeze. A constraint at the relative pose, limited to that force, holds the part without the creep
        # and pivoting of Bullet's soft contacts under a sustained squeeze; a part whose weight and inertia need
        # more is dragged out of it, and :meth:`_check_friction_grasps` lets it go.
        end = self.link_index(self.robot.arm(arm).end_effector)
        link_state = pybullet.getLinkState(self.robot_id, end, computeForwardKinematics=True,
                                           physicsClientId=self.client)
        relative = np.linalg.inv(_transform(link_state[0], link_state[1])) @ self.object_transform(name)
        cid = _fix(self.robot_id, end, self._body(name).body_id, relative, self.client)
        # the fingers stop where they closed on it (a little inside): the grasp constraint is the squeeze
        closed_on = pybullet.getJointStates(self.robot_id, list(self._finger_links[arm]), physicsClientId=self.client)
        self.set_joint_targets({joint: state[0] + _HOLD_SQUEEZE * (1.0 if shut > opened else -1.0)
                                for joint, state, shut, opened in zip(gripper.joints, closed_on, gripper.closed,
                                                                      gripper.open, strict=True)})
        capacity = _FINGER_FRICTION * self._body(name).model.lateral_friction * fingers * gripper.force
        pybullet.changeConstraint(cid, maxForce=capacity, physicsClientId=self.client)
        self._grasps[arm] = _Grasp(arm, name, cid, friction=True, relative=relative)
        return True

    def _check_friction_grasps(self, slide: float = 0.005) -> None:
        for arm, grasp in list(self._grasps.items()):
            if not grasp.friction:
                continue
            assert grasp.relative is not None
            end = self.link_index(self.robot.arm(arm).end_effector)
            state = pybullet.getLinkState(self.robot_id, end, computeForwardKinematics=True,
                                          physicsClientId=self.client)
            now = np.linalg.inv(_transform(state[0], state[1])) @ self.object_transform(grasp.object_name)
            slid = float(np.linalg.norm(now[:3, 3] - grasp.relative[:3, 3])) > slide
            touching = self.touching_fingers(grasp.object_name, arm, _HOLD_TOUCH) == len(self._finger_links[arm])
            grasp.lost = 0 if touching else grasp.lost + 1
            if (slid and not touching) or grasp.lost >= _LOST_AFTER:  # slipped out: the fingers hold nothing
                pybullet.removeConstraint(grasp.constraint_id, physicsClientId=self.client)
                del self._grasps[arm]
            elif slid:  # pushed along the pads (pressed onto a support), still squeezed: held where it is now
                self._reseat(grasp, now)

    def _reseat(self, grasp: _Grasp, relative: np.ndarray) -> None:
        """Hold a friction-grasped part at ``relative`` (its pose in the end-effector link's frame now), with the
        same strength: a part pressed up into the fingers or dragged along them while both still squeeze it has
        slid, not dropped -- friction holds it wherever the pads now grip it."""
        capacity = pybullet.getConstraintInfo(grasp.constraint_id, physicsClientId=self.client)[10]
        pybullet.removeConstraint(grasp.constraint_id, physicsClientId=self.client)
        end = self.link_index(self.robot.arm(grasp.arm).end_effector)
        grasp.constraint_id = _fix(self.robot_id, end, self._body(grasp.object_name).body_id, relative, self.client)
        pybullet.changeConstraint(grasp.constraint_id, maxForce=capacity, physicsClientId=self.client)
        grasp.relative = relative

    def release(self, arm: str | None = None) -> str | None:
        """Let go of what the arm holds (its name, or ``None``). Hand-object collisions come back once they no
        longer overlap, so the object does not get kicked out of the fingers; a friction gripper opens its
        fingers a few millimetres wider than the part."""
        arm = arm or self.robot.default_arm
        grasp = self._grasps.pop(arm, None)
        if grasp is None:
            return None
        if grasp.friction:
            pybullet.removeConstraint(grasp.constraint_id, physicsClientId=self.client)
            self._open_to(arm, self.width_across(grasp.object_name, arm) + 2.0 * _PRESHAPE_MARGIN)
            return grasp.object_name
        pybullet.removeConstraint(grasp.constraint_id, physicsClientId=self.client)
        self._pending_collision.append((arm, grasp.object_name))
        self._restore_collisions()
        return grasp.object_name

    def held(self, arm: str | None = None) -> str | None:
        arm = arm or self.robot.default_arm
        grasp = self._grasps.get(arm)
        return grasp.object_name if grasp else None

    def grasped_relative(self, arm: str | None = None) -> np.ndarray | None:
        """4x4 pose of the held object in the end-effector's URDF frame that the grasp holds it to (where it
        was grasped; contact can press it out of that for a while); ``None`` if nothing is held."""
        arm = arm or self.robot.default_arm
        grasp = self._grasps.get(arm)
        if grasp is None or grasp.relative is None:
            return None
        link = self.robot.arm(arm).end_effector
        state = pybullet.getLinkState(self.robot_id, self.link_index(link), computeForwardKinematics=True,
                                      physicsClientId=self.client)
        return np.linalg.inv(self.link_transform(link)) @ _transform(state[0], state[1]) @ grasp.relative

    def holds_by_friction(self, arm: str | None = None) -> bool:
        """Whether the arm holds something by its fingers' friction (it may turn or slide in them)."""
        arm = arm or self.robot.default_arm
        grasp = self._grasps.get(arm)
        return grasp is not None and grasp.friction

    def grasp_transform(self, arm: str | None = None) -> np.ndarray | None:
        """4x4 pose of the held object in the end-effector frame (``None`` if nothing is held): the kinematic
        relation that turns a wanted object pose into a gripper pose (object = gripper @ this)."""
        arm = arm or self.robot.default_arm
        grasp = self._grasps.get(arm)
        if grasp is None:
            return None
        return np.linalg.inv(self.link_transform(self.robot.arm(arm).end_effector)) @ self.object_transform(
            grasp.object_name
        )

    def robot_contacts(self) -> list[tuple[str, str]]:
        """(robot link, object name or ``"table"``) for every contact of the robot with the world, sorted."""
        names = self._link_name
        out: set[tuple[str, str]] = set()
        for contact in pybullet.getContactPoints(bodyA=self.robot_id, physicsClientId=self.client):
            other = contact[2]
            if other == self.robot_id:
                continue
            what = "table" if other == self.table_id else self._by_id.get(other) or self.obstacle_name_of(other)
            if what is not None:
                out.add((names.get(contact[3], str(contact[3])), what))
        return sorted(out)

    def _distance_to_gripper(self, body: int, end_link: str) -> float:
        pos = self.link_transform(end_link)[:3, 3]
        probe = pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=1e-4, physicsClientId=self.client)
        probe_body = pybullet.createMultiBody(0.0, probe, -1, list(pos), physicsClientId=self.client)
        try:
            points = pybullet.getClosestPoints(probe_body, body, 1.0, physicsClientId=self.client)
        finally:
            pybullet.removeBody(probe_body, physicsClientId=self.client)
        if not points:
            return math.inf
        return max(0.0, min(p[8] for p in points) + 1e-4)

    def _restore_collisions(self) -> None:
        still: list[tuple[str, str]] = []
        for arm, name in self._pending_collision:
            if name not in self._bodies:
                continue
            body = self._bodies[name].body_id
            links = self._hand_links[arm]
            overlapping = any(
                pybullet.getClosestPoints(self.robot_id, body, 0.0, linkIndexA=link, physicsClientId=self.client)
                for link in links
            )
            if overlapping:
                still.append((arm, name))
                continue
            self._hand_collisions(body, links, True)
        self._pending_collision = still

    def _hand_collisions(self, body: int, hand: Sequence[int], enabled: bool) -> None:
        """Switch collisions between the hand's links and every link of an object's body on or off."""
        for part in range(-1, pybullet.getNumJoints(body, physicsClientId=self.client)):
            for link in hand:
                pybullet.setCollisionFilterPair(self.robot_id, body, link, part, int(enabled),
                                                physicsClientId=self.client)

    # -- magnetic attach -------------------------------------------------------------------------------------

    def attachment_relation(self, active: str, reference: str) -> AttachmentRelation:
        """R_p, R_n and the attach rule between two objects' primary features (base frame)."""
        ap_a, an_a = self.feature(active)
        ap_r, an_r = self.feature(reference)
        return attachment_relation(
            ap_a,
            an_a,
            ap_r,
            an_r,
            position_tolerance=self.attach_position_tolerance,
            angle_tolerance=self.attach_angle_tolerance,
        )

    def try_attach(self, active: str, reference: str) -> bool:
        """Join the two objects with a fixed constraint if the attach rule holds (or they are joined already)."""
        if frozenset((active, reference)) in self._joins:
            return True
        if not self.attachment_relation(active, reference).aligned:
            return False
        self.join(active, reference)
        return True

    def join(self, active: str, reference: str) -> None:
        """Join two objects rigidly as they stand, without checking the attach rule: the join has happened
        elsewhere (a model of the scene told of it by the robot, :mod:`bt_meta.ros2.world`)."""
        pair = frozenset((active, reference))
        if pair in self._joins:
            return
        a, r = self._body(active), self._body(reference)
        ta, tr = self.object_transform(active), self.object_transform(reference)
        rel = np.linalg.inv(tr) @ ta
        self._object_collisions(a.body_id, r.body_id, False)
        self._joins[pair] = _fix(r.body_id, -1, a.body_id, rel, self.client)

    def detach(self, a: str, b: str) -> bool:
        """Undo a magnetic join (for resetting scenes); True if there was one."""
        cid = self._joins.pop(frozenset((a, b)), None)
        if cid is None:
            return False
        pybullet.removeConstraint(cid, physicsClientId=self.client)
        self._object_collisions(self._body(a).body_id, self._body(b).body_id, True)
        return True

    def _object_collisions(self, first: int, second: int, enabled: bool) -> None:
        """Switch collisions between every link of two objects' bodies on or off."""
        c = self.client
        for a in range(-1, pybullet.getNumJoints(first, physicsClientId=c)):
            for b in range(-1, pybullet.getNumJoints(second, physicsClientId=c)):
                pybullet.setCollisionFilterPair(first, second, a, b, int(enabled), physicsClientId=c)

    def attachments(self) -> list[tuple[str, str]]:
        """Joined pairs, each sorted by name."""
        return sorted(tuple(sorted(p)) for p in self._joins)  # type: ignore[misc]

    def _magnet_pairs(self) -> list[tuple[str, str]]:
        actives = [n for n, b in self._bodies.items() if b.model.role == "active"]
        references = [n for n, b in self._bodies.items() if b.model.role == "reference"]
        return [(a, r) for a in actives for r in references]

    # -- helpers ---------------------------------------------------------------------------------------------

    def _body(self, name: str) -> _Body:
        try:
            return self._bodies[name]
        except KeyError:
            known = ", ".join(self._bodies) or "none"
            raise SimulationError(f"no object named {name!r} in the simulation; objects: {known}") from None

    @staticmethod
    def _checked_pose(pose: Sequence[float], what: str) -> Pose6:
        values = tuple(float(v) for v in pose)
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise SimulationError(f"{what}: a pose is 6 finite numbers (x, y, z, roll, pitch, yaw), got {pose!r}")
        return values  # type: ignore[return-value]


def _fix(parent_body: int, parent_link: int, child_body: int, rel: np.ndarray, client: int) -> int:
    """A fixed constraint holding ``child_body`` at ``rel`` (4x4) in the parent link's frame, as strong as a grasp."""
    cid = pybullet.createConstraint(
        parent_body,
        parent_link,
        child_body,
        -1,
        pybullet.JOINT_FIXED,
        [0.0, 0.0, 0.0],
        list(rel[:3, 3]),
        [0.0, 0.0, 0.0],
        list(_quat(rel[:3, :3])),
        [0.0, 0.0, 0.0, 1.0],
        physicsClientId=client,
    )
    pybullet.changeConstraint(cid, maxForce=2000.0, physicsClientId=client)
    return cid


def _transform(pos: Sequence[float], quat: Sequence[float]) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = np.array(pybullet.getMatrixFromQuaternion(quat)).reshape(3, 3)
    out[:3, 3] = pos
    return out


def _quat(rot: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) quaternion of a rotation matrix (Shepperd's method: stable for every rotation)."""
    m = rot
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return (float(x), float(y), float(z), float(w))
