"""Collision checking of the robot against itself and a scene, with coal through Pinocchio geometry models.

Offers:

* :class:`CollisionChecker` -- the robot's collision geometry (URDF primitives and meshes), self-collision pairs
  minus the SRDF's disabled pairs, and a scene of named boxes, cylinders and spheres that can be added, moved,
  removed, attached to a robot frame (carried) and detached at run time
* :class:`Contact` -- the first colliding pair found, by name, with its penetration depth when coal gives one
* :class:`SceneObject` -- what the checker knows of one scene object
* :func:`pose_from_xyz_rpy` -- a pose from position and roll/pitch/yaw, the form object states use
* :func:`as_se3` -- a pose from an SE3, a 4x4 matrix, (x, y, z) or (x, y, z, roll, pitch, yaw)
* :data:`TABLE` -- the name of the table top among the scene objects
* :data:`SHRINK` -- how much smaller than the simulated objects the worlds make their collision shapes

Robot geometries are reported by link name (``right_gripper_base_link``); scene objects by their own name.
Pairs checked: robot against robot (minus the SRDF's and rigidly joined ones), robot against every scene object,
and a carried object against the fixed ones (fixed objects never move relative to each other, so they are not
paired; touching counts as colliding, so a block placed on another needs :meth:`CollisionChecker.allow`).
A full check goes through an AABB-tree broad phase first (~25 us when nothing collides, ~110 us for the ordered
pass over every pair that names the first colliding one).
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from bt_meta.errors import KinematicsError
from bt_meta.model_cache import cached, file_signature
from bt_meta.world.kinematics.forward import Kinematics, se3_from_matrix

__all__ = ["SHRINK", "TABLE", "CollisionChecker", "Contact", "SceneObject", "pose_from_xyz_rpy"]

Pose = pin.SE3 | np.ndarray | Sequence[float]


SHRINK = 0.0015
"""Collision shapes are this much (m) smaller on every side than the simulated ones (the simulated world builds them
so): blocks placed side by side touch exactly, which is not a collision (pybullet, too, lets resting bodies overlap a
little)."""

TABLE = "table"
"""The scene object a world adds as the table top: carried objects keep no clearance from it (what they are lifted
from and lowered onto)."""


def pose_from_xyz_rpy(x: float, y: float, z: float, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> pin.SE3:
    return pin.SE3(pin.rpy.rpyToMatrix(roll, pitch, yaw), np.array([x, y, z], dtype=float))


def as_se3(pose: Pose) -> pin.SE3:
    """A pose from an SE3, a 4x4 matrix, (x, y, z) or (x, y, z, roll, pitch, yaw)."""
    if isinstance(pose, pin.SE3):
        return pin.SE3(pose)
    array = np.asarray(pose, dtype=float)
    if array.shape == (4, 4):
        return se3_from_matrix(array)
    if array.shape == (3,):
        return pose_from_xyz_rpy(*array)
    if array.shape == (6,):
        return pose_from_xyz_rpy(*array)
    raise KinematicsError(f"a pose is an SE3, a 4x4 matrix, (x, y, z) or (x, y, z, roll, pitch, yaw); got {pose!r}")


@dataclass(frozen=True)
class Contact:
    """A colliding pair: robot links by link name, scene objects by object name."""

    first: str
    second: str
    kind: str
    """``self`` (robot against robot) or ``scene`` (involving a scene object)."""
    penetration: float | None = None
    """Penetration depth in metres when coal reports a contact (positive = overlapping)."""

    @property
    def pair(self) -> tuple[str, str]:
        return (self.first, self.second)

    def __str__(self) -> str:
        depth = f" (penetration {self.penetration * 1000:.1f} mm)" if self.penetration is not None else ""
        return f"{self.first} <-> {self.second}{depth}"


@dataclass(frozen=True)
class SceneObject:
    name: str
    shape: str
    """``box``, ``cylinder``, ``sphere`` or ``convex``."""
    dimensions: tuple[float, ...]
    """box: (size x, size y, size z); cylinder: (radius, length along z); sphere: (radius,); convex: (points,)."""
    attached_to: str | None
    """The robot frame carrying the object, or None when it is fixed in the base frame."""


class CollisionChecker:
    """Self-collision and scene collision of one robot, for a whole configuration ``q``."""

    def __init__(self, kinematics: Kinematics) -> None:
        self.kinematics = kinematics
        model = kinematics.model
        robot = kinematics.robot
        self._model = model
        self._data = model.createData()
        robot_geometry, self._disabled_links = _robot_geometry(model, robot)
        self.geometry: pin.GeometryModel = robot_geometry.copy()  # the scene's objects go into this copy
        self._robot_geometries = self.geometry.ngeoms
        self._link_of = [model.frames[g.parentFrame].name for g in self.geometry.geometryObjects]
        self._objects: dict[str, SceneObject] = {}
        self._fixed: set[str] = {TABLE}
        """Scene objects nothing pushes aside (the table, static obstacles): a carried object never presses in."""
        self._allowed: set[frozenset[str]] = set()
        self._geometry_data: pin.GeometryData | None = None
        self._broadphase = None
        self._pair_kinds: list[str] = []
        self._masks: dict[tuple[bool, bool, str | None], np.ndarray] = {}
        self._active_key: tuple[bool, bool, str | None] | None = None
        self._self_pairs: list[tuple[int, int]] | None = None
        self._pairs = np.zeros((0, 2), dtype=int)
        """Every pair the model holds (Pinocchio's ``collisionPairs``, in order): all that the rules could pair
        among the geometry objects there are now."""
        self._checked = np.zeros(0, dtype=bool)
        """Which of :attr:`_pairs` the rules pair now (the rest stay inactive in the geometry data)."""
        self._model_stale = True
        """Geometry objects were added or removed: the model's pairs and the geometry data are made anew."""
        self._applied: np.ndarray | None = None
        """The pair activations the geometry data has now."""
        self._touched: np.ndarray | None = None
        """Pairs whose narrow phase may have run since the data was last as made (active at some check)."""
        self._measured: set[int] = set()
        """Pairs whose distance was computed since then."""
        self._stale_guesses = False
        """The pairs changed since the last check: the warm starts are put back before the next one."""
        self._rebuild_pairs()

    # -- pairs -------------------------------------------------------------------------------------------------

    def _name_of(self, geometry_index: int) -> str:
        if geometry_index < self._robot_geometries:
            return self._link_of[geometry_index]
        return self.geometry.geometryObjects[geometry_index].name

    def _rebuild_pairs(self) -> None:
        """Robot pairs minus the SRDF's, then every robot geometry against every scene object, minus allowed.

        The model holds every pair the rules could make among its geometry objects, set once per set of objects;
        a grasp, a release or an allowed touch only switches pairs on and off in the geometry data (a new
        ``GeometryData`` for each pair set cost 2-10 ms, about 40 times an episode)."""
        geometry = self.geometry
        objects = geometry.geometryObjects
        n_robot = self._robot_geometries
        if self._self_pairs is None:  # the robot's own pairs never change: found once
            self._self_pairs = [
                (i, j) for i in range(n_robot) for j in range(i + 1, n_robot)
                # rigidly joined geometries never move relative to each other
                if objects[i].parentJoint != objects[j].parentJoint
                and frozenset((self._link_of[i], self._link_of[j])) not in self._disabled_links]
        # One boolean map handed over at once: adding ~1,600 pairs one by one cost ~15 ms per rebuild, and a
        # grasp, a release or an allowed touch rebuilds. The map is filled a row of robot geometries at a time
        # (reading each geometry object through the bindings once), not pair by pair.
        active = np.zeros((geometry.ngeoms, geometry.ngeoms), dtype=bool)
        if self._self_pairs:
            rows, columns = zip(*self._self_pairs, strict=True)
            active[list(rows), list(columns)] = True
        joints = np.array([g.parentJoint for g in objects], dtype=int)
        names = [g.name for g in objects]
        links = np.array(self._link_of, dtype=object)
        allowed_with: dict[str, set[str]] = {}
        for pair in self._allowed:
            first, second = (*pair, *pair)[:2]  # a pair of one name stands for (name, name)
            allowed_with.setdefault(first, set()).add(second)
            allowed_with.setdefault(second, set()).add(first)
        robot_joints = joints[:n_robot]
        for j in range(n_robot, geometry.ngeoms):
            carried_by = joints[j]
            partners = allowed_with.get(names[j], set())
            row = np.ones(n_robot, dtype=bool)
            if carried_by != 0:  # not against what is rigidly joined to the carrying link
                row &= robot_joints != carried_by
            if partners:
                row &= ~np.isin(links, list(partners))
            active[:n_robot, j] = row
            # A carried object can hit the other objects; fixed objects never move relative to each other.
            for i in range(n_robot, j):
                other = joints[i]
                if (carried_by == 0 and other == 0) or carried_by == other or names[i] in partners:
                    continue
                active[i, j] = True
        if self._model_stale:
            # every self pair the rules keep (they never change) and every pair with a scene object
            possible = np.zeros_like(active)
            if self._self_pairs:
                possible[list(rows), list(columns)] = True
            possible[:, n_robot:] = True
            possible = np.triu(possible, 1)
            geometry.setCollisionPairs(possible, True)
            self._pairs = np.argwhere(possible)  # setCollisionPairs adds them in this (row-major) order
            self._pair_kinds = ["self" if second < n_robot else "scene" for second in self._pairs[:, 1].tolist()]
            self._geometry_data = None
            self._broadphase = None
            self._applied = None
            self._model_stale = False
        elif self._geometry_data is not None:
            self._stale_guesses = True
        self._checked = active[self._pairs[:, 0], self._pairs[:, 1]]
        self._masks = {}
        self._carried: dict[bool, list[int]] | None = None
        self._active_key = None

    def _as_made(self) -> None:
        """Put the geometry data back as ``createData`` made it, but for its pair activations: coal warm-starts
        each pair's narrow phase from its last result (the cached guesses in the requests), and the broad phase's
        tree follows its updates; a fresh data per pair set reset both, and the checks must answer as they did
        then to the last digit (a penetration depth, which pair the broad phase reaches first)."""
        data = self._geometry_data
        guess, hint = np.array([1.0, 0.0, 0.0]), np.zeros(2, dtype=np.int32)
        requests = data.collisionRequests
        for k in np.flatnonzero(self._touched).tolist():
            request = requests[k]
            request.cached_gjk_guess = guess
            request.cached_support_func_guess = hint
        requests = data.distanceRequests
        for k in self._measured:
            request = requests[k]
            request.cached_gjk_guess = guess
            request.cached_support_func_guess = hint
        self._touched = np.zeros(len(self._pairs), dtype=bool)
        self._measured = set()
        self._active_key = None  # the next check marks the pairs it activates as touched
        self._broadphase = None
        self._stale_guesses = False

    @property
    def geometry_data(self) -> pin.GeometryData:
        """The geometry data of the model's pairs (activations as :meth:`_activate` last set them)."""
        if self._geometry_data is None:
            self._geometry_data = self.geometry.createData()
            for request in self._geometry_data.collisionRequests:
                request.enable_contact = True
            self._applied = np.ones(len(self._pairs), dtype=bool)  # createData activates every pair
            self._touched = np.zeros(len(self._pairs), dtype=bool)
            self._measured = set()
            self._active_key = None
            self._broadphase = None
            self._stale_guesses = False
        elif self._stale_guesses:
            self._as_made()
        if self._broadphase is None:
            self._broadphase = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
                self._model, self.geometry, self._geometry_data
            )
        return self._geometry_data

    @property
    def checked_pairs(self) -> list[tuple[int, int]]:
        """The pairs (geometry indices, first < second, in the order they are checked) the rules pair now."""
        return [tuple(p) for p in self._pairs[self._checked].tolist()]

    @property
    def n_self_pairs(self) -> int:
        return int(np.count_nonzero(self._checked & (np.array(self._pair_kinds, dtype=object) == "self")))

    @property
    def n_scene_pairs(self) -> int:
        return int(np.count_nonzero(self._checked & (np.array(self._pair_kinds, dtype=object) == "scene")))

    @property
    def links(self) -> tuple[str, ...]:
        """Robot links that carry collision geometry."""
        return tuple(dict.fromkeys(self._link_of))

    # -- the scene ---------------------------------------------------------------------------------------------

    @property
    def objects(self) -> dict[str, SceneObject]:
        return dict(self._objects)

    def add_box(self, name: str, size: Sequence[float], pose: Pose) -> None:
        """A box of full side lengths ``size`` centred at ``pose``."""
        sx, sy, sz = _positive(size, 3, "box size")
        self._add(SceneObject(name, "box", (sx, sy, sz), None), coal.Box(sx, sy, sz), pose)

    def add_cylinder(self, name: str, radius: float, length: float, pose: Pose) -> None:
        """A cylinder whose axis is the z axis of ``pose``, centred at ``pose``."""
        r, h = _positive((radius, length), 2, "cylinder radius and length")
        self._add(SceneObject(name, "cylinder", (r, h), None), coal.Cylinder(r, h), pose)

    def add_convex(self, name: str, points: np.ndarray, pose: Pose) -> None:
        """The convex hull of ``points`` ((n, 3), in the frame of ``pose``): a mesh object as pybullet collides it."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) < 4:
            raise KinematicsError(f"convex {name!r}: a hull needs at least 4 points, got {len(points)}")
        vertices = coal.StdVec_Vec3s()
        for point in points:
            vertices.append(point)
        self._add(SceneObject(name, "convex", (float(len(points)),), None),
                  coal.Convex.convexHull(vertices, False, "Qt"), pose)

    def add_sphere(self, name: str, radius: float, pose: Pose) -> None:
        (r,) = _positive((radius,), 1, "sphere radius")
        self._add(SceneObject(name, "sphere", (r,), None), coal.Sphere(r), pose)

    def _add(self, description: SceneObject, shape: coal.CollisionGeometry, pose: Pose) -> None:
        name = description.name
        if not name:
            raise KinematicsError("a scene object needs a name")
        if name in self._objects or name in self._link_of:
            raise KinematicsError(f"scene object {name!r} already exists (or names a robot link)")
        placement = as_se3(pose)
        self.geometry.addGeometryObject(pin.GeometryObject(name, 0, 0, placement, shape))
        self._objects[name] = description
        self._model_stale = True
        self._rebuild_pairs()

    def _index(self, name: str) -> int:
        if name not in self._objects:
            known = ", ".join(self._objects) or "none"
            raise KinematicsError(f"unknown scene object {name!r}; scene objects: {known}")
        return int(self.geometry.getGeometryId(name))

    def move(self, name: str, pose: Pose) -> None:
        """Place an object at ``pose`` in the base frame (it stops being carried if it was)."""
        index = self._index(name)
        obj = self.geometry.geometryObjects[index]
        if obj.parentJoint != 0:
            self.detach(name, pose)
            return
        obj.placement = as_se3(pose)

    def pose(self, name: str, q: np.ndarray | None = None) -> pin.SE3:
        """Where an object is; a carried object's pose depends on ``q`` (default home)."""
        index = self._index(name)
        obj = self.geometry.geometryObjects[index]
        if obj.parentJoint == 0:
            return pin.SE3(obj.placement)
        q = self.kinematics.home if q is None else self.kinematics.check_q(q)
        pin.forwardKinematics(self._model, self._data, q)
        return self._data.oMi[obj.parentJoint] * obj.placement

    def remove(self, name: str) -> None:
        self._index(name)
        self.geometry.removeGeometryObject(name)
        del self._objects[name]
        self._allowed = {pair for pair in self._allowed if name not in pair}
        self._model_stale = True
        self._rebuild_pairs()

    def clear_scene(self) -> None:
        for name in list(self._objects):
            self.geometry.removeGeometryObject(name)
        self._objects.clear()
        self._allowed.clear()
        self._model_stale = True
        self._rebuild_pairs()

    def allow(self, name: str, others: Iterable[str]) -> None:
        """Stop checking ``name`` against these robot links or scene objects.

        E.g. a block against the fingers that hold it, or a carried block against the block it is placed on.
        """
        self._allow(name, others)
        self._rebuild_pairs()

    def _allow(self, name: str, others: Iterable[str]) -> None:
        self._index(name)
        for other in others:
            if other not in self._link_of and other not in self._objects:
                raise KinematicsError(
                    f"unknown collision link or scene object {other!r}; links: {', '.join(self.links)}; "
                    f"objects: {', '.join(self._objects) or 'none'}"
                )
            self._allowed.add(frozenset((name, other)))

    def disallow(self, name: str) -> None:
        """Check ``name`` against every robot link again."""
        self._index(name)
        self._allowed = {pair for pair in self._allowed if name not in pair}
        self._rebuild_pairs()

    def attach(self, name: str, frame: str, q: np.ndarray, allow: Iterable[str] = ()) -> None:
        """Carry an object with robot ``frame``, keeping its current pose relative to that frame at ``q``.

        The object is then no longer checked against geometries rigidly joined to the carrying link, nor against
        the links or objects in ``allow`` (typically the gripper's fingers, which move on their own joints).
        """
        if allow:
            self._allow(name, allow)  # the pairs are rebuilt once, below
        index = self._index(name)
        fid = self.kinematics.frame_id(frame)
        world = self.pose(name, q)
        pin.forwardKinematics(self._model, self._data, self.kinematics.check_q(q))
        joint = self._model.frames[fid].parentJoint
        obj = self.geometry.geometryObjects[index]
        obj.parentJoint = joint
        obj.parentFrame = fid
        obj.placement = self._data.oMi[joint].actInv(world)
        self._objects[name] = SceneObject(name, self._objects[name].shape, self._objects[name].dimensions, frame)
        self._rebuild_pairs()

    def detach(self, name: str, pose: Pose | None = None, q: np.ndarray | None = None) -> None:
        """Fix a carried object in the base frame: at ``pose``, or where it is at configuration ``q``.

        Links and objects it was allowed to touch stay allowed; :meth:`disallow` forgets them.
        """
        index = self._index(name)
        if pose is None:
            if q is None:
                raise KinematicsError(f"detach({name!r}) needs the pose to leave it at, or the configuration q")
            pose = self.pose(name, q)
        obj = self.geometry.geometryObjects[index]
        obj.parentJoint = 0
        obj.parentFrame = 0
        obj.placement = as_se3(pose)
        self._objects[name] = SceneObject(name, self._objects[name].shape, self._objects[name].dimensions, None)
        self._rebuild_pairs()

    # -- queries -----------------------------------------------------------------------------------------------

    def check(
        self, q: np.ndarray, *, scene: bool = True, self_collision: bool = True, arm: str | None = None,
        carried_clearance: float = 0.0,
    ) -> Contact | None:
        """The first colliding pair at ``q`` (pairs in a fixed order: deterministic), or None if collision-free.

        ``arm`` restricts the check to pairs with a geometry moved by that arm's joints (what an arm motion can
        change: about half the pairs); ``scene`` and ``self_collision`` choose the kinds of pairs.
        ``carried_clearance`` (m): a carried object closer than this to another scene object collides with it (a
        block carried past others must not graze them: the shapes here are a little smaller than the simulated
        ones, so that blocks set side by side do not collide, and a graze in the simulator tips the other over).
        Negative, it may press that far into another object before it collides (a block set down snug between
        neighbours that were nudged a few millimetres its way: the simulator pushes them back). The table is
        never in these pairs.
        """
        q = self.kinematics.check_q(q)
        key = (scene, self_collision, arm)
        data, mask = self._activate(key)
        margins = self._carried_pairs(movable_only=carried_clearance < 0.0) if carried_clearance != 0.0 else []
        # Broad phase first (AABB tree: ~25 us instead of ~110 us when nothing collides); it visits pairs in its
        # own order, so a collision is named by the ordered pass below.
        if (not margins and key == (True, True, None)
                and not pin.computeCollisions(self._model, self._data, self._broadphase, q, True)):
            return None
        pin.updateGeometryPlacements(self._model, self._data, self.geometry, data, q)
        for k in margins:
            data.collisionRequests[k].security_margin = carried_clearance
        try:
            if not pin.computeCollisions(self.geometry, data, True):
                return None
        finally:
            for k in margins:
                data.collisionRequests[k].security_margin = 0.0
        results = data.collisionResults
        # Results of inactive pairs and of pairs after the first hit are stale: look only at active ones, in order.
        for k in np.flatnonzero(mask).tolist():
            if results[k].isCollision():
                return self._contact(k, results[k])
        return None  # pragma: no cover - computeCollisions said there was one

    def fix(self, name: str) -> None:
        """Mark scene object ``name`` as fixed (a static obstacle): a carried object may never press into it."""
        self._fixed.add(name)
        self._carried = None

    def _carried_pairs(self, movable_only: bool = False) -> list[int]:
        """Indices of the pairs of a carried object and another scene object but the table (what it is lifted from
        and lowered onto) -- with ``movable_only``, nor a fixed one (:meth:`fix`); found once per set of pairs (a
        move checks every waypoint, a planned path hundreds)."""
        if self._carried is None:
            n_robot = self._robot_geometries
            objects = self.geometry.geometryObjects
            pairs = [(k, objects[first].name, objects[second].name)
                     for k, (first, second) in enumerate(self._pairs.tolist())
                     if first >= n_robot and second >= n_robot and self._checked[k]]
            self._carried = {
                False: [k for k, a, b in pairs if TABLE not in (a, b)],
                True: [k for k, a, b in pairs if not ({a, b} & self._fixed)]}
        return self._carried[movable_only]

    def all_contacts(self, q: np.ndarray) -> list[Contact]:
        """Every colliding pair at ``q`` (slower than :meth:`check`: no early stop)."""
        q = self.kinematics.check_q(q)
        data, mask = self._activate((True, True, None))
        pin.updateGeometryPlacements(self._model, self._data, self.geometry, data, q)
        pin.computeCollisions(self.geometry, data, False)
        results = data.collisionResults
        return [self._contact(k, results[k]) for k in np.flatnonzero(mask).tolist() if results[k].isCollision()]

    def _mask(self, key: tuple[bool, bool, str | None]) -> np.ndarray:
        mask = self._masks.get(key)
        if mask is None:
            scene, self_collision, arm = key
            kinds = np.array(self._pair_kinds)
            mask = np.zeros(len(kinds), dtype=bool)
            if scene:
                mask |= kinds == "scene"
            if self_collision:
                mask |= kinds == "self"
            if arm is not None:
                moved = self._joints_moved_by(arm)
                joints = np.array([g.parentJoint for g in self.geometry.geometryObjects], dtype=int)
                moved_geometry = np.isin(joints, list(moved))
                mask &= moved_geometry[self._pairs[:, 0]] | moved_geometry[self._pairs[:, 1]]
            mask &= self._checked
            self._masks[key] = mask
        return mask

    def _joints_moved_by(self, arm: str) -> set[int]:
        arm_joints = {self._model.getJointId(name) for name in self.kinematics.robot.arm(arm).joints}
        return {j for j in range(self._model.njoints) if arm_joints & set(self._model.supports[j])}

    def _activate(self, key: tuple[bool, bool, str | None]) -> tuple[pin.GeometryData, np.ndarray]:
        """Geometry data with exactly the wanted pairs active (switched only when the wish or the pairs change,
        and then only the pairs that differ)."""
        data = self.geometry_data
        mask = self._mask(key)
        if self._active_key != key:
            for k in np.flatnonzero(mask != self._applied).tolist():
                if mask[k]:
                    data.activateCollisionPair(k)
                else:
                    data.deactivateCollisionPair(k)
            self._applied = mask.copy()
            self._touched |= mask
            self._active_key = key
        return data, mask

    def in_collision(self, q: np.ndarray) -> bool:
        return self.check(q) is not None

    def distance(self, q: np.ndarray, name: str) -> tuple[float, str]:
        """Smallest distance between scene object ``name`` and the robot, and the closest link."""
        index = self._index(name)
        q = self.kinematics.check_q(q)
        data = self.geometry_data
        pin.updateGeometryPlacements(self._model, self._data, self.geometry, data, q)
        best, link = np.inf, ""
        for k, pair in enumerate(self.geometry.collisionPairs):
            if pair.second != index or not self._checked[k]:
                continue
            self._measured.add(k)
            result = pin.computeDistance(self.geometry, data, k)
            if result.min_distance < best:
                best, link = float(result.min_distance), self._link_of[pair.first]
        if not link:
            raise KinematicsError(f"scene object {name!r} is not checked against any robot link")
        return best, link

    def _contact(self, k: int, result: coal.CollisionResult) -> Contact:
        pair = self.geometry.collisionPairs[k]
        depth = None
        if result.numContacts() > 0:
            depth = float(-result.getContact(0).penetration_depth)
            depth = abs(depth)
        return Contact(self._name_of(pair.first), self._name_of(pair.second), self._pair_kinds[k], depth)


def _positive(values: Sequence[float], count: int, what: str) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if len(out) != count or not all(np.isfinite(v) and v > 0 for v in out):
        raise KinematicsError(f"{what} must be {count} positive numbers, got {tuple(values)!r}")
    return out


def _robot_geometry(model: pin.Model, robot: Any) -> tuple[pin.GeometryModel, frozenset[frozenset[str]]]:
    """The robot's collision geometry parsed from its URDF (meshes included) and the SRDF's disabled pairs, once
    per process (:mod:`bt_meta.model_cache`): callers copy the geometry model before adding to it; the
    copies share the immutable coal shapes."""
    key = ("collision geometry", file_signature(robot.urdf_path), file_signature(robot.srdf_path),
           tuple(str(p) for p in robot.package_dirs), model.njoints, model.nframes)

    def parse() -> tuple[pin.GeometryModel, frozenset[frozenset[str]]]:
        geometry = pin.buildGeomFromUrdf(model, str(robot.urdf_path), pin.GeometryType.COLLISION,
                                         package_dirs=[str(p) for p in robot.package_dirs])
        disabled = _srdf_disabled_pairs(robot.srdf_path) if robot.srdf_path else set()
        return geometry, frozenset(disabled)

    return cached(key, parse)


def _srdf_disabled_pairs(path) -> set[frozenset[str]]:
    root = ElementTree.fromstring(path.read_text(encoding="utf-8"))
    return {frozenset((el.get("link1", ""), el.get("link2", ""))) for el in root.iter("disable_collisions")}
