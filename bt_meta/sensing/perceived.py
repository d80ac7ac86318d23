"""The perceived symbolic state: what monitors compare with comes from sensing, not from the world's bookkeeping.

The simulated world bookkeeps the symbolic effects of every skill that reported success, so a symbolic
expectation compared with that state can never fail. :class:`PerceivedState` is a perception plugin that, after
every successful step, re-derives each *perceivable* atom of the believed state from sensing and drops the ones
sensing contradicts (identity-bearing facts such as ``shape(b5, 1x2)`` stay: identical blocks cannot be told apart
by looking). Its ``symbolic_state`` observation wins over the ground-truth plugin's (it is registered later, so
called first), and the monitor adopts it as the new belief. Perceivable atoms, by predicate:

* ``at(block, x, y)`` (a task frame in the grounding, e.g. the letters) -- the noisy top view shows a block
  colour (any colour the scene format defines, :mod:`bt_meta.perception.colours`, the frame's lighting balanced
  against the table's colour) over every unit cell the block's believed shape covers there (grid-map occupancy,
  :mod:`bt_meta.perception.topview`: at least 3 of the 4 half-lb cells of each unit cell); a cell the robot's
  own body hides in part (its self-filter: the segmentation of its links) is not perceivable then
* ``at(pose)`` -- the gripper's pose (proprioception) is within 2.5 cm of the pose the symbol grounds to, for
  absolute and anchored poses (a pose relative to an object moves with the object once it is held, a ``turn_up``
  pose is grounded from how the part is held: not judged)
* ``holding(part)`` -- the gripper holds that part (gripper sensing: the grasp constraint / finger contact)
* ``on_table(part)`` -- not held, and its sensed lowest point within 1.5 cm of the table top
* ``upright(part)`` -- its sensed up axis within 25 degrees of the vertical
* ``inserted(part, feature)`` -- its sensed centre within 1.5 cm (horizontally) of the feature's point

Sensing is fallible (:mod:`bt_meta.sensing.noise`): noisy, variably lit frames from a camera whose believed pose
is off, with the arm in view; noisy object poses.

Offers:

* :class:`PerceivedState` -- the plugin (``bt_meta_observe``), seeded
* :func:`perceived_plugins` -- ``[(name, plugin)]`` to add to a plugin host for a perceived-world run
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from typing import Any

import numpy as np

from bt_meta.plugins import hookimpl
from bt_meta.sensing.noise import SensingNoise, corrupt_image, pose_error, sense_pose

__all__ = ["PerceivedState", "perceived_plugins"]

CELL_OCCUPIED = 3
"""Of the 4 grid-map cells (0.5 lb each) covering a unit cell, at least this many show a block colour."""
OCCLUDED = 0.05
"""A unit cell (with a half-lb margin) more than this fraction covered by the robot in the image is occluded:
not perceivable now (a robot self-filter masks its own body; what it hid cannot be judged)."""
BLOCK_TOP = 0.6
"""lb: height of a Mega Blok's top face (its studs excluded) above the table."""
POSE_TOLERANCE = 0.025
TABLE_TOLERANCE = 0.015
UPRIGHT_TOLERANCE = math.radians(25.0)
INSERTED_TOLERANCE = 0.015
TABLE_COLOUR = (0.93, 0.9, 0.83, 1.0)
"""The simulator's table (RGBA), the lighting is balanced against when the world does not say."""


class PerceivedState:
    """Derives the perceivable atoms of the believed state from (noisy) sensing; see the module docstring."""

    def __init__(self, seed: int = 0, noise: SensingNoise | None = None) -> None:
        self.seed = int(seed)
        self.noise = noise or SensingNoise()
        self.frames = 0
        self.calibration = pose_error(SensingNoise.rng(self.seed, 1), self.noise.camera_translation_sigma,
                                      self.noise.camera_rotation_sigma_deg)
        self._cameras: weakref.WeakKeyDictionary[Any, Any] = weakref.WeakKeyDictionary()

    # -- sensing ----------------------------------------------------------------------------------------------

    def _camera(self, sim: Any) -> Any:
        camera = self._cameras.get(sim)
        if camera is None:
            from bt_meta.world.simulation.camera import TopViewCamera

            camera = TopViewCamera(sim, hide_robot=not self.noise.occlusion)
            self._cameras[sim] = camera
        return camera

    def look(self, world: Any) -> Any:
        """One noisy top view, analysed (blocks with colour, shape, centroid) with the thresholds of every colour the
        scene format defines, on the table's colour: a green block at its cell is seen there, like a blue one. The
        frame's lighting is first balanced against the table's declared colour (the greys are told by value)."""
        from bt_meta.perception.colours import balance_to_background, scene_thresholds
        from bt_meta.perception.hsv import PlaneProjection
        from bt_meta.perception.topview import analyse

        camera = self._camera(world.sim)
        image = camera.capture(depth=True, segmentation=self.noise.occlusion)
        robot = None
        if image.segmentation is not None:  # the robot's self-filter: it knows where its own body is in view
            robot = (image.segmentation & 0xFFFFFF) == world.sim.robot_id
        image = corrupt_image(image, self.noise, SensingNoise.rng(self.seed, 2, self.frames), self.calibration)
        self.frames += 1
        projection = PlaneProjection.from_image(image, world.sim.table.top_z)
        table = getattr(world.sim.table, "colour", None) or TABLE_COLOUR
        view = analyse(balance_to_background(image.rgb, table), projection, depth=image.depth,
                       thresholds=scene_thresholds(table))
        view.robot_mask = robot  # type: ignore[attr-defined]
        view.camera = camera  # type: ignore[attr-defined]
        return view

    def sensed_pose(self, world: Any, name: str) -> np.ndarray:
        transform = world.sim.object_transform(name)
        distance = 1.0  # the top camera is 1 m above the table
        self.frames += 1
        return sense_pose(transform, self.noise, SensingNoise.rng(self.seed, 3, self.frames), self.calibration,
                          distance)

    # -- the rules ----------------------------------------------------------------------------------------------

    def _rule(self, world: Any, atom: tuple[str, ...], believed: Any, view: Callable[[], Any]) -> bool | None:
        """True / False: sensing confirms / contradicts ``atom``; None: not perceivable."""
        from bt_meta.world.simulation.objects import LB

        name, args = atom[0], atom[1:]
        sim = world.sim
        try:
            if name == "at" and len(args) == 3:
                frame = _place_frame(world)
                if frame is None:
                    return None
                shape = next((a[2] for a in believed.atoms_of("shape") if len(a) == 3 and a[1] == args[0]), None)
                u, v = float(args[1]), float(args[2])
                cells = [(u - 0.5, v), (u + 0.5, v)] if shape == "1x2" else [(u, v)]
                top = sim.table.top_z + BLOCK_TOP * LB
                seen = [_occupied(view(), world.ground_cell(frame, str(cu), str(cv))[:2], top) for cu, cv in cells]
                return None if None in seen else all(seen)
            if name == "at" and len(args) == 1:
                spec = world.pose_spec(args[0])
                if not ("pose" in spec or "anchor" in spec) or "turn_up" in spec:
                    # a pose relative to an object (``above: part``) moves with it once it is held, and a turn
                    # toward a part's base is grounded from how it is held: where the gripper went cannot be
                    # re-derived from where the object is now
                    return None
                target = world.ground_pose(args[0])
                gripper = sim.link_transform(world.end_effector(world.default_arm))
                return float(np.linalg.norm(gripper[:3, 3] - target[:3, 3])) <= POSE_TOLERANCE
            if name == "holding" and len(args) == 1:
                part = world.object_name(args[0])
                return any(sim.held(arm) == part for arm in sim.robot.arms)
            if name == "on_table" and len(args) == 1:
                part = world.object_name(args[0])
                if any(sim.held(arm) == part for arm in sim.robot.arms):
                    return False
                pose = self.sensed_pose(world, part)
                points = sim.object_model(part).points() @ pose[:3, :3].T + pose[:3, 3]
                return float(points[:, 2].min()) - sim.table.top_z <= TABLE_TOLERANCE
            if name == "upright" and len(args) == 1:
                pose = self.sensed_pose(world, world.object_name(args[0]))
                return math.acos(max(-1.0, min(1.0, float(pose[2, 2])))) <= UPRIGHT_TOLERANCE
            if name == "inserted" and len(args) == 2:
                part = world.object_name(args[0])
                obj, feature = world.feature_of(args[1])
                point, _ = sim.feature(obj, feature)
                pose = self.sensed_pose(world, part)
                return math.hypot(pose[0, 3] - point[0], pose[1, 3] - point[1]) <= INSERTED_TOLERANCE
        except Exception:  # a symbol the world cannot ground is not perceivable here
            return None
        return None

    @hookimpl
    def bt_meta_observe(self, world: Any, context: Any) -> dict[str, Any] | None:
        if world is None or getattr(world, "sim", None) is None or not hasattr(world, "symbolic_state"):
            return None
        believed = world.symbolic_state()
        cache: list[Any] = []

        def view() -> Any:
            if not cache:
                cache.append(self.look(world))
            return cache[0]

        contradicted = [atom for atom in believed if self._rule(world, atom, believed, view) is False]
        perceived = believed.apply(delete=contradicted) if contradicted else believed
        evidence: dict[str, Any] = {"contradicted": [list(a) for a in contradicted], "frames": self.frames}
        if cache:
            evidence["blocks"] = [{"colour": b.colour, "shape": b.shape, "centroid": list(b.centroid)}
                                  for b in cache[0].blocks]
        return {"symbolic_state": perceived, "perceived": evidence}


def _occupied(view: Any, point: Any, top: float) -> bool | None:
    """Does the noisy top view show a block colour over the unit cell centred at ``point`` (a grid-map of the
    window: blobs of touching blocks merge, occupancy does not)? ``None`` when the robot's own body covers most of
    the cell in the image (occluded: nothing can be said)."""
    from bt_meta.world.simulation.objects import LB

    mask = getattr(view, "robot_mask", None)
    if mask is not None:
        camera = view.camera
        u, v = camera.table_to_pixel(float(point[0]), float(point[1]), top)
        half = max(1, round(LB / camera.metres_per_pixel(top)))
        window = mask[max(0, int(v) - half):int(v) + half, max(0, int(u) - half):int(u) + half]
        if window.size == 0 or float(window.mean()) > OCCLUDED:
            return None
    occupancy = np.asarray(view.grid_map_at((float(point[0]), float(point[1])), z=top).occupancy)
    rows, columns = occupancy.shape
    centre = occupancy[rows // 2 - 1:rows // 2 + 1, columns // 2 - 1:columns // 2 + 1]
    return int(np.count_nonzero(centre)) >= CELL_OCCUPIED


def _place_frame(world: Any) -> str | None:
    for spec in world.grounding.skills.values():
        if spec.get("frame"):
            return str(spec["frame"])
    return None


def perceived_plugins(seed: int, noise: SensingNoise | None = None) -> list[tuple[str, Any]]:
    return [("perceived_state", PerceivedState(seed, noise))]
