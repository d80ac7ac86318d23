"""The expected outcome of a variant, decided from ground truth: the true scene in the simulator, not by hand.

The variant's scene is built in pybullet, moved by the start noise a campaign episode of seed :data:`START_SEED`
applies (so the label is for the scene that episode runs) and settled; then, in this order (the first that applies
wins):

1. ``unrepairable`` -- the objects on the table cannot make the goal. Letters: the letter's cells (from the
   nominal plan: every ``place`` with its block's shape) need ``U`` units; with ``n1`` 1x1 and ``n2`` 1x2 blocks
   present and at most ``M`` disjoint pairs of neighbouring cells a 1x2 can cover (side by side along the
   letter's x: the place skill lays a 1x2 that way), the letter can be drawn iff
   ``n1 + 2 min(n2, M) >= U``. Other families: every object the problem names is present with its type, or a
   spare of that type is.
2. ``limit:reachability`` / ``limit:collision`` -- kinematics and collision checks on the true scene: for every
   object the robot must pick up (the needed ones, else spares that could stand in), mink IK to the top-down
   grasp pose the skills use (a friction gripper's end-effector below the part's top, its fingers open, as the
   pick solves its way down), collision-checked against the robot and the scene (the hand may touch the object
   grasped; a letters block on another face: also the turn the place skill's ``turn`` mode would make from that
   grasp; the motions between, against static obstacles, by the ways move_to takes: the joint-space line, the
   gripper's straight line, a lift first, a planned path). A role no candidate can fill: the failed solve's kind
   (``reachability`` beats ``collision``). A place
   where the task puts something that an object the task does not name occupies (its centre near; for a letter
   cell, any part of it inside the cell's footprint): ``limit:collision``; a block the task names lying on another
   block's cell is moved by the plan: ``repairable`` (step 3), and so is a letters block the run takes for a missing
   one (of the missing block's shape and graspable, whether or not the named blocks could tile the letter another
   way: the goal counts cells occupied; of its colour first where the task's symbols name colours, then one lying
   on a cell, then by name: as the substitution chooses) and its cell is filled after the missing block's step. A
   part turned off its up axis that the domain cannot bring to its place is a limit of the kind its own step
   meets (held as it lies, set upright above and at its place: no IK solution even through obstacles,
   ``reachability``; every solution collides, ``collision``). When several limits apply and the plan
   step each stops is known (letters), the label is the one the plan meets first (an obstacle at the fourth
   placement before a block out of reach at the fifth); otherwise the first found in this order.
3. ``repairable`` -- the goal can be reached but not by the nominal plan: a needed object is missing or of
   another type (substitution), lies on a cell where the task puts another block, has another colour where the
   task's symbols name colours (its initial facts),
   is turned off its nominal up axis by more than 20 degrees (re-orientation / pose repair), or a fixture the
   nominal plan's absolute poses depend on moved more than 1 cm.
4. ``nominal_equivalent`` -- otherwise (shifts, turns about the vertical, distractors clear of the work, colours
   the task does not name): the nominal plan still succeeds.

Offers:

* :class:`Labeller` -- ``label(scene_path, variant, changes)`` -> :class:`Label`; ``targets``; a context manager
  owning one simulator for many variants
* :class:`Label` -- expected outcome, reason, evidence
* :data:`OUTCOMES` -- the five expected outcomes
* :func:`letter_cells` / :func:`max_pairs` / :func:`letters_feasible` -- the inventory rule of the letters
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["OUTCOMES", "Label", "Labeller", "letter_cells", "letters_feasible", "max_pairs"]

OUTCOMES = ("nominal_equivalent", "repairable", "limit:reachability", "limit:collision", "unrepairable")

UP_TOLERANCE = math.radians(20.0)
FIXTURE_TOLERANCE = 0.01
BLOCKING_RADIUS = 0.6
"""An object whose centre is within this many lb (x, y) of a place the task puts something blocks it."""
GRASP_HEIGHT = 0.004
"""Gripper above the object's top at the grasp (the place and move_to skills use 2-4 mm)."""
APPROACH_HEIGHT = 0.08
PATH_STEPS = 24
"""Waypoints checked on a joint-space line (move_to checks one per tick: about as many for these motions)."""
CANDIDATES = 3
"""Objects tried per place before it counts as blocked (the nominal one first)."""
PROBE_HEIGHT = 0.02
"""Height (m) of the footprint probe above a letter cell, from just above the table: anything resting there."""
START_SEED = 0
"""The seed of the start noise the labels describe: a campaign episode moves every object by the demo's seeded
noise before it starts (:func:`bt_meta.judge.noise.jitter`, up to 3 mm and 2 degrees), and the label is for the
scene the episode runs -- the first (by default the only) seed's. Labelled without it, a green 1x2 was 6.5 mm into a
cell of H and 5.7 mm in the run, below what the place takes as room (generated letters_H s1 0058). ``None``: the
scene exactly as written (hand-built cases)."""
GRASP_TURNS = (0.0, 90.0, -90.0, 45.0, -45.0, 135.0, -135.0, 180.0)
"""Grasp yaws (degrees about the vertical, from the skills' own) tried before a part counts as out of reach."""
ARRIVAL_YAWS = tuple(range(0, 360, 30))
"""Yaws (degrees) about a target feature's normal tried for a part brought onto it as it is held."""
REORIENT_PREFIX = "Reorient"
"""Tasks so named re-orient a part by a regrasp (the ``reorientation`` repair plugin's convention)."""


@dataclass(frozen=True)
class Label:
    expected: str
    reason: str
    evidence: dict[str, Any] = field(default_factory=dict)


def letter_cells(plan: Iterable[Any], shapes: dict[str, str], actions: Iterable[str]
                 ) -> list[tuple[float, float]]:
    """The unit cells (lb) a plan fills through ``actions`` (primitives putting a block at a frame's cell):
    ``place(b, x, y)`` covers (x, y), or for a 1x2 the two cells half a unit either side along the letter's x."""
    cells: list[tuple[float, float]] = []
    actions = set(actions)
    for action in plan:
        if action.name not in actions:
            continue
        block, x, y = action.args[0], float(action.args[1]), float(action.args[2])
        cells += [(x + dx, y) for dx in _cell_offsets(shapes.get(block))]
    return cells


def _cell_offsets(shape: str | None) -> tuple[float, ...]:
    """The x offsets (lb) of the unit cells a block covers from its centre: a 1x2 lies along the letter's x."""
    return (-0.5, 0.5) if shape == "1x2" else (0.0,)


def max_pairs(cells: Sequence[tuple[float, float]]) -> int:
    """The most disjoint pairs of neighbouring cells a 1x2 can cover: one lb apart along the letter's x, as the
    place skill lays a 1x2 (a leg's cells, one above the other, take 1x1 blocks only)."""
    edges = [(i, j) for i in range(len(cells)) for j in range(i + 1, len(cells))
             if abs(cells[i][1] - cells[j][1]) < 1e-6 and abs(abs(cells[i][0] - cells[j][0]) - 1.0) < 1e-6]

    def best(used: frozenset[int], start: int) -> int:
        top = 0
        for k in range(start, len(edges)):
            i, j = edges[k]
            if i not in used and j not in used:
                top = max(top, 1 + best(used | {i, j}, k + 1))
        return top

    return best(frozenset(), 0)


def letters_feasible(units: int, pairs: int, n1: int, n2: int) -> bool:
    """Can ``n1`` 1x1 and ``n2`` 1x2 blocks fill ``units`` cells with at most ``pairs`` 1x2 placements?"""
    return n1 + 2 * min(n2, pairs) >= units


class Labeller:
    """Labels the variants of one family; owns one headless simulator reused for every variant."""

    def __init__(self, family: Any, scene: Any, start_seed: int | None = START_SEED, robot: Any = None) -> None:
        from bt_meta.campaign.families import derived_fixtures, derived_grasped, needed_objects
        from bt_meta.htn import load_task_file
        from bt_meta.htn.planner import plan
        from bt_meta.world.robot.description import RobotDescription, load_robot
        from bt_meta.world.simulation.sim import Simulation
        from bt_meta.world.simulation.sim_world import load_grounding, quiet_stdout

        self.family = family
        self.scene = scene
        self.start_seed = start_seed
        self._grasp_turn: dict[str, float] = {}
        """Object -> the grasp yaw (radians, from the skills' own) found reachable in the variant labelled now."""
        task_path = family.task_path()
        self.task_file = load_task_file(task_path)
        self.problem = self.task_file.problem(family.problem)
        self.grounding = load_grounding(self.task_file.domain.name, task_path)
        self.needed = needed_objects(self.problem, self.grounding)
        self.nominal = {o.name: o for o in scene.objects}
        facts = list(self.problem.state) if hasattr(self.problem, "state") else []
        self.shapes = {str(f[1]): str(f[2]) for f in facts if len(f) == 3 and f[0] == "shape"}
        self.colour_symbols = {str(f[1]) for f in facts if len(f) == 3 and f[0] == "colour"}
        result = plan(self.task_file.domain, self.problem)
        self.plan = list(result.plan) if result.ok else []
        # primitives that put a part at a cell of a frame (the grounding gives their skill a `frame`)
        self.cell_actions = {name for name, spec in self.grounding.skills.items() if spec.get("frame")}
        chosen = robot if robot is not None else self.grounding.robot or "baxter"
        self.robot = chosen if isinstance(chosen, RobotDescription) else load_robot(chosen)
        with quiet_stdout():
            import pybullet  # noqa: F401  (prints its build time on import)

            self.sim = Simulation(seed=0, visuals="light", robot=self.robot)
        world = self._world(scene.path, None)
        try:
            present = list(world.sim.object_names())
            self.target_features: list[tuple[str, str | None]] = []
            """(object, feature) of each of :attr:`targets` a part is put onto (none for a frame's cells)."""
            self.grasped: tuple[str, ...] = (family.grasped if family.grasped is not None
                                             else derived_grasped(self.plan, self.grounding, present))
            positions = {name: world.sim.object_transform(name)[:2, 3] for name in present}
            self.absolute_fixtures: tuple[str, ...] = (
                family.absolute_fixtures if family.absolute_fixtures is not None
                else derived_fixtures(self.plan, self.grounding, positions, world.sim.robot.scene_offset))
            self.targets = self._targets(world)
            self.nominal_up = {name: _up(world.sim.object_transform(name)) for name in world.sim.object_names()}
            self.nominal_xy = {name: world.sim.object_transform(name)[:2, 3].copy()
                               for name in world.sim.object_names()}
            self.jobs = self._jobs(world)
            self.nominal_held = self._held_as_demonstrated(world)
        finally:
            world.close()
        self.cells = letter_cells(self.plan, self.shapes, self.cell_actions)
        placed = [self.nominal.get(self.grounding.objects.get(str(a.args[0]), str(a.args[0])))
                  for a in self.plan if a.name in self.cell_actions]
        self.on_cells = bool(self.cells) and all(o is not None and o.model().shape in ("1x1", "1x2") for o in placed)
        """The task puts Mega Bloks on a frame's cells: the inventory rule decides what can be drawn (any block of a
        shape fills a cell). A task placing other parts (a pin into a kit's slot) needs each part or a spare of its
        type, as every other task does."""
        self.reorientable = any(str(task).startswith(REORIENT_PREFIX) for task in self.task_file.domain.tasks)

    def _held_as_demonstrated(self, world: Any) -> dict[str, np.ndarray]:
        """Object type -> the part in the gripper's frame as the nominal scene's top-down grasp holds it."""
        out: dict[str, np.ndarray] = {}
        for name in self.grasped:
            if name in world.sim.object_names():
                out.setdefault(world.sim.object_model(name).type,
                               np.linalg.inv(self._grasp(world, name)) @ world.sim.object_transform(name))
        return out

    def _over(self, world: Any, name: str, height: float) -> np.ndarray:
        """The top-down gripper pose ``height`` over ``name``'s top, at the yaw the skills pick it at turned by the
        grasp yaw :meth:`_graspable` found reachable (none found yet: the skills' own)."""
        from bt_meta.world.skills.place import GRIPPER_YAW, nearest_yaw, object_yaw, symmetry, top_down

        transform = world.sim.object_transform(name)
        yaw = nearest_yaw(object_yaw(transform), symmetry(world.sim.object_model(name)), GRIPPER_YAW)
        yaw += self._grasp_turn.get(name, 0.0)
        return top_down(transform[0, 3], transform[1, 3], world.stack_top(name) + height, yaw)

    def _grasp(self, world: Any, name: str) -> np.ndarray:
        """The top-down gripper pose at the grasp of ``name``, as the pick makes it: a fixed-constraint gripper
        :data:`GRASP_HEIGHT` over its top; a friction gripper (the Panda's) with its end-effector below the top, so
        the open finger pads overlap the part (:meth:`~bt_meta.world.simulation.sim_world.SimWorld.grasp_height`):
        the fingers reach down beside it, where a neighbour can be in their way."""
        pose = self._over(world, name, GRASP_HEIGHT)
        height = world.grasp_height(name, world.default_arm, GRASP_HEIGHT)
        if height != GRASP_HEIGHT:
            pose[2, 3] = world.object_top(name) + height
        return pose

    def _open_around(self, world: Any, name: str, q: np.ndarray) -> np.ndarray:
        """``q`` with a friction gripper's fingers open as the pick has them when it solves its way down to
        ``name``: fully open (the pick opens them just wider than the part as it starts down, but its move's IK
        is solved while they still stand open, and a neighbour an open finger meets there fails the grasp
        ``collision``). Set from the robot description, not from the simulator's fingers, which keep whatever the
        last variant labelled left them at. Other grippers: ``q`` as it is."""
        sim = world.sim
        gripper = sim.robot.arm(world.default_arm).gripper
        if gripper is None or not gripper.joints or not sim.grasps_by_friction(name, world.default_arm):
            return q
        return world.kin.q_from_dict(dict(zip(gripper.joints, gripper.open, strict=True)), q)

    def __enter__(self) -> Labeller:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.sim.close()

    # -- worlds ---------------------------------------------------------------------------------------------

    def _world(self, scene_path: str | Path, variant: str | None) -> Any:
        from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

        # Absolute: the grounding resolves a relative scene path against its own folder, not the caller's.
        setup = {"scene": str(Path(scene_path).resolve())}
        grounding = dataclasses.replace(self.grounding, problems={**self.grounding.problems,
                                                                  self.problem.name: setup})
        with quiet_stdout():
            world = SimWorld(self.task_file.domain, self.problem, grounding, variant=variant, seed=0, sim=self.sim,
                             robot=self.robot)
        if self.start_seed is not None:
            from bt_meta.judge.noise import jitter

            try:
                jitter(world, self.start_seed)
            except BaseException:
                world.close()
                raise
        return world

    def _targets(self, world: Any) -> list[tuple[float, float, float]]:
        """Where the task puts things (x, y, z): the letter's cells, or the feature / part the held one goes to."""
        out: list[tuple[float, float, float]] = []
        frame = next((spec.get("frame") for spec in self.grounding.skills.values() if spec.get("frame")), None)
        for action in self.plan:
            if action.name in self.cell_actions and frame is not None:
                shape = self.shapes.get(action.args[0])
                x, y = float(action.args[1]), float(action.args[2])
                for dx in _cell_offsets(shape):
                    gx, gy, _ = world.ground_cell(str(frame), str(x + dx), str(y))
                    out.append((gx, gy, self._floor(world, str(frame), gx, gy)))
        if out:
            return out
        grasped = set(self.grasped)
        for name in self.needed:
            # a part the robot only carries is no target; one the plan's absolute poses were taught over is, even
            # when the plan picks it up afterwards (the tutorial's base, lifted to show the joint)
            if (name in grasped and name not in self.absolute_fixtures) or name not in world.sim.object_names():
                continue
            feature_names = [s.get("feature") for s in self.grounding.features.values() if s.get("object") == name]
            feature = feature_names[0] if feature_names and feature_names[0] else None
            point, _ = world.sim.feature(name, feature)
            out.append((float(point[0]), float(point[1]), float(point[2])))
            self.target_features.append((name, feature))
        return out

    def _supports(self) -> set[str]:
        """The objects and obstacles the grounding's frames name as ``support:``: where parts are put, so never
        what occupies or blocks a place."""
        return {str(spec["support"]) for spec in self.grounding.frames.values() if spec.get("support")}

    @staticmethod
    def _floor(world: Any, frame: str, x: float, y: float) -> float:
        """The height a part put at (x, y) of ``frame`` rests on, as the place skill takes it: the top of the
        frame's support there (a tray's floor, the block it is stacked on), else the table top."""
        _, support = world.frame_support(frame)
        table = float(world.sim.table.top_z)
        if support is None:
            return table
        top = world.surface_under(support, np.array([[x, y]]))
        return table if top is None else max(float(top), table)

    def _occupied_cell(self, world: Any, names: Sequence[str]) -> Label | None:
        """``limit:collision`` when an object reaches into a letter cell's footprint deeper than the place skill's
        :func:`~bt_meta.world.skills.place.place_overlap` (where the place fails): with its centre further than
        :data:`BLOCKING_RADIUS` away, a block turned or longer than a cell still takes room the placed block needs.
        Ground truth: the simulator's closest points."""
        from bt_meta.world.simulation.objects import LB
        from bt_meta.world.skills.place import place_overlap

        frame = next((spec.get("frame") for spec in self.grounding.skills.values() if spec.get("frame")), None)
        if frame is None:
            return None
        sim = world.sim
        overlap = place_overlap()
        for step, action in enumerate(self.plan):
            if action.name not in self.cell_actions:
                continue
            shape = self.shapes.get(action.args[0])
            x, y = float(action.args[1]), float(action.args[2])
            for dx in _cell_offsets(shape):
                gx, gy, yaw = world.ground_cell(str(frame), str(x + dx), str(y))
                pose = np.eye(4)
                c, s_ = math.cos(yaw), math.sin(yaw)
                pose[:2, :2] = [[c, -s_], [s_, c]]
                pose[:3, 3] = (gx, gy, self._floor(world, str(frame), gx, gy) + 0.002 + PROBE_HEIGHT / 2.0)
                near = {n: d for n, d in sim.box_clearances((LB, LB, PROBE_HEIGHT), pose, names, 0.0).items()
                        if d < -overlap and n != str(action.args[0])}  # a block on its own cell is picked
                if near:
                    name, gap = min(near.items(), key=lambda item: item[1])
                    return Label("limit:collision", f"{name} reaches into the cell ({x + dx:g}, {y:g}) where the "
                                 f"task puts {action.args[0]} ({-gap * 1000:.1f} mm into its footprint)",
                                 {"object": name, "target": [round(gx, 4), round(gy, 4)], "gap": round(gap, 5),
                                  "step": step})
        return None

    def _jobs(self, world: Any) -> list[tuple[str | None, tuple[float, float, float]]]:
        """(the object the nominal plan puts there, where): each letter ``place`` at its centre; for the other
        families each grasped object to each of :attr:`targets`."""
        frame = next((spec.get("frame") for spec in self.grounding.skills.values() if spec.get("frame")), None)
        out: list[tuple[str | None, tuple[float, float, float]]] = []
        for action in self.plan:
            if action.name in self.cell_actions and frame is not None:
                gx, gy, _ = world.ground_cell(str(frame), str(action.args[1]), str(action.args[2]))
                out.append((str(action.args[0]), (gx, gy, self._floor(world, str(frame), gx, gy))))
        if out:
            return out
        return [(name, target) for name in self.grasped
                for target, (owner, _) in zip(self.targets, self.target_features, strict=True) if owner != name]

    # -- the label ------------------------------------------------------------------------------------------

    def label(self, scene_path: str | Path, variant: str | None, changes: Sequence[dict[str, Any]] = ()) -> Label:
        world = self._world(scene_path, variant)
        self._grasp_turn = {}
        try:
            return self._label(world)
        finally:
            world.close()

    def _label(self, world: Any) -> Label:
        from bt_meta.world.simulation.objects import LB

        sim = world.sim
        present = {name: sim.object_model(name) for name in sim.object_names()}
        roles = self._roles(present)
        if isinstance(roles, Label):
            return roles
        # 2. kinematics and collisions on the true scene
        feasible: dict[str, tuple[bool, str | None, str]] = {}
        for name in sorted({c for candidates in roles.values() for c in candidates}):
            feasible[name] = self._graspable(world, name)
        # Every limit the checks find, with the plan step it stops: the run meets the earliest (a limit whose
        # step is unknown keeps its place in the order below).
        limits: list[Label] = []
        limit = self._fill(roles, feasible, present)
        if limit is not None:
            limits.append(limit)
        fixtures = {n for n in self.needed if not self.on_cells and n not in self.grasped}
        # only what the task does not name blocks a place: an object the plan uses is picked up by the plan, and
        # so is one it takes for a missing block
        # a frame's support (the tray, the block a part is stacked on) is where the part goes, not in its way
        named = set(self.needed) | self._stand_ins(world, present, feasible) | self._supports()
        steps = self._target_steps()
        for index, (tx, ty, _) in enumerate(self.targets):
            blocking = next((name for name in present if name not in fixtures and name not in named and math.hypot(
                *(sim.object_transform(name)[:2, 3] - (tx, ty))) < BLOCKING_RADIUS * LB), None)
            if blocking is not None:
                limits.append(Label("limit:collision", f"{blocking} occupies a place the task puts something "
                                    f"({tx:.3f}, {ty:.3f})", {"object": blocking, "target": [tx, ty],
                                                              "step": steps.get(index)}))
                break
        occupied = self._occupied_cell(world, [n for n in present if n not in fixtures and n not in named])
        if occupied is not None:
            limits.append(occupied)
        blocked = self._obstacle_label(world, roles, feasible, present) if sim.obstacles() else None
        if blocked is not None and blocked.expected.startswith("limit:"):
            limits.append(blocked)
        if limits:
            if all(limit.evidence.get("step") is not None for limit in limits):
                return min(limits, key=lambda limit: limit.evidence["step"])  # the first wins a tie
            return limits[0]
        if blocked is not None:
            return blocked
        # 3. repairable or nominal-equivalent
        lying = self._occupied_cell(world, [n for n in present if n in named])
        if lying is not None:  # a block the plan uses lies on another's cell: it must be moved first
            return Label("repairable", lying.reason + "; the plan must move it first", lying.evidence)
        for name in self.needed:
            nominal = self.nominal.get(name)
            if name not in present or nominal is None:
                return Label("repairable", f"{name} is missing; others can stand in", {"object": name})
            if name in feasible and not feasible[name][0]:
                return Label("repairable", f"{name} cannot be grasped ({feasible[name][1]}); others can stand in",
                             {"object": name, "kind": feasible[name][1]})
            if present[name].type != nominal.type:
                return Label("repairable", f"{name} is a {present[name].type}, not a {nominal.type}",
                             {"object": name})
            if name in self.colour_symbols and nominal.colour is not None and present[name].colour != nominal.colour:
                return Label("repairable", f"{name} is {present[name].colour} where the task's symbols say "
                             f"{nominal.colour}", {"object": name})
            if name in self.nominal_up:
                angle = _angle(_up(sim.object_transform(name)), self.nominal_up[name])
                if angle > UP_TOLERANCE:
                    turned = f"{name} is turned {math.degrees(angle):.0f} deg off its nominal up axis"
                    way = self._turned_way(world, name, feasible)
                    if way is None:
                        kind, why = self._nominal_arrival(world, name) or self._fixture_arrival(world, name) or (
                            "reachability", "no grasp as the parts lie brings one onto the other within reach")
                        return Label(f"limit:{kind}", f"{turned}; the domain offers no re-orientation and {why}",
                                     {"object": name, "degrees": math.degrees(angle), "step": self._step_of(name),
                                      "kind": kind})
                    return Label("repairable", f"{turned} ({way})", {"object": name,
                                                                      "degrees": math.degrees(angle)})
            if name in self.absolute_fixtures and name in self.nominal_xy:
                moved = float(np.linalg.norm(sim.object_transform(name)[:2, 3] - self.nominal_xy[name]))
                if moved > FIXTURE_TOLERANCE:
                    return Label("repairable", f"{name} moved {moved * 100:.1f} cm; the nominal plan's poses "
                                 "for it are absolute", {"object": name, "moved": moved})
        return Label("nominal_equivalent", "every needed object present, reachable, upright; nothing in the way")

    def _roles(self, present: dict[str, Any]) -> dict[str, list[str]] | Label:
        """Role -> candidate objects (the needed object first, then stand-ins); ``unrepairable`` when the table
        cannot make the goal."""
        grasped = None if self.on_cells else self.grasped
        if self.on_cells:
            blocks = {n: m for n, m in present.items() if m.shape in ("1x1", "1x2") and n not in self._supports()}
            n1 = sum(m.shape == "1x1" for m in blocks.values())
            n2 = sum(m.shape == "1x2" for m in blocks.values())
            units, pairs = len(self.cells), max_pairs(self.cells)
            if not letters_feasible(units, pairs, n1, n2):
                return Label("unrepairable", f"the letter needs {units} cells; {n1} 1x1 and {n2} 1x2 blocks "
                             f"cover at most {n1 + 2 * min(n2, pairs)}", {"units": units, "n1": n1, "n2": n2})
            return {"blocks": sorted(blocks)}
        roles: dict[str, list[str]] = {}
        for name in self.needed:
            nominal = self.nominal.get(name)
            if nominal is None:
                continue
            spares = [n for n, m in present.items() if m.type == nominal.type and n not in self.needed]
            candidates = ([name] if name in present and present[name].type == nominal.type else []) + spares
            if not candidates:
                return Label("unrepairable", f"no {nominal.type} on the table for {name}", {"object": name})
            if grasped is not None and name in grasped:
                roles[name] = candidates
        return roles

    def _turned_way(self, world: Any, name: str, feasible: dict[str, tuple[bool, str | None, str]]) -> str | None:
        """How a correct system gets the goal with ``name`` turned off its nominal up axis -- by the domain's own
        means, on the true scene -- or None when nothing does. A block on a frame's cell is turned where it lies
        (checked with its grasp) when the domain can turn it (a ``turn``-mode place or a ``Reorient...`` task).
        A part the robot carries is re-oriented by a ``Reorient...`` task the domain offers, or held as it lies (a
        top-down grasp) and turned in the hand so its primary feature meets its target's (:meth:`_feature_arrival`).
        A target turned (a fixture) keeps its feature where it now faces: every part carried onto it must meet it so.
        An object that is neither is followed by poses relative to it."""
        if self.on_cells:  # turned where it lies, by the domain's own means (letters: turn_over / Reorient)
            turns = any(spec.get("mode") == "turn" for spec in self.grounding.skills.values())
            if self.reorientable or turns:
                return "re-orientation or pose repair"
            # no turn: the place itself stands it up on the way, held as it was picked (the gripper tilted)
            return "set down upright as it is held" if self._nominal_arrival(world, name) is None else None
        if self.reorientable and name in self.grasped and feasible.get(name, (True, None, ""))[0]:
            return "the domain's re-orientation"
        owned = [feature for owner, feature in self.target_features if owner == name]
        if owned:
            carried = [p for p in self.grasped if p != name and p in world.sim.object_names()]
            if all(any(self._feature_arrival(world, p, name, f) for f in owned) for p in carried):
                return "what goes onto it is brought onto its feature as it lies"
            return None
        if name not in self.grasped:
            return "followed by poses relative to it"
        for owner, feature in self.target_features:
            if owner != name and self._feature_arrival(world, name, owner, feature):
                return f"held as it lies, its feature brought onto {owner}'s"
        return None

    def _nominal_arrival(self, world: Any, name: str) -> tuple[str, str] | None:
        """Why the nominal plan's own step cannot put the turned ``name`` where it goes -- (kind, what failed) -- or
        None when it can (or the plan carries it nowhere). The step's way, in the order a run meets it: the part
        grasped top-down as it lies at the skills' own yaw, brought to its target standing as the nominal plan puts
        it (the place turns it on the way, so the gripper holds the part's tilt), first above the target, then down
        onto it. The kind is the physical obstacle at the first pose that fails: ``reachability`` when the arm has
        no solution there even through obstacles, ``collision`` when every solution runs into the scene (a Panda's
        hand into the tray where a Baxter's arm cannot reach at all)."""

        target = next((t for n, t in self.jobs if n == name), None)
        if target is None:
            return None
        grasp = self._skills_grasp(world, name)
        blocked = self._first_blocked(world, self._placing(world, name, grasp, target), world.current_q(), target)
        return None if blocked is None else (blocked[0], f"{name}, held as it lies and set upright, {blocked[1]}")

    def _skills_grasp(self, world: Any, name: str) -> np.ndarray:
        """:meth:`_grasp` of ``name`` at the skills' own yaw (the one the run takes), whatever turn a check set."""
        kept = self._grasp_turn.pop(name, None)
        try:
            return self._grasp(world, name)
        finally:
            if kept is not None:
                self._grasp_turn[name] = kept

    def _placing(self, world: Any, name: str, grasp: np.ndarray, target: Any) -> tuple[np.ndarray, np.ndarray]:
        """The gripper poses above ``target`` and down at it that set ``name``, held by ``grasp``, where the
        nominal plan puts it."""
        as_grasped = np.linalg.inv(grasp) @ world.sim.object_transform(name)
        held, goal = self._arrivals(world, name, as_grasped, target)[0]
        down = goal @ np.linalg.inv(held)
        above = down.copy()
        above[2, 3] += APPROACH_HEIGHT
        return above, down

    @staticmethod
    def _first_blocked(world: Any, poses: tuple[np.ndarray, np.ndarray], q: np.ndarray, target: Any
                       ) -> tuple[str, str] | None:
        """(kind, where and why) of the first of the poses above and down at ``target`` the arm cannot take from
        ``q`` in turn, or None when it takes both."""
        import pinocchio as pin

        at = f"({target[0]:.3f}, {target[1]:.3f})"
        for pose, where in zip(poses, (f"above {at}", f"down at {at}"), strict=True):
            result = world.ik.solve(world.default_arm, pin.SE3(pose[:3, :3], pose[:3, 3]), q, seed=0)
            if not result.success:
                return str(result.kind or "reachability"), f"{where}: {result.message}"
            q = result.q
        return None

    def _fixture_arrival(self, world: Any, name: str) -> tuple[str, str] | None:
        """Why the nominal plan's step cannot bring a part onto the turned fixture ``name`` -- (kind, what failed)
        -- or None (``name`` is no such fixture, or that step gets there and the limit comes later). The step's way,
        as a run meets it: the first part the plan carries onto ``name`` (in the plan's order), grasped top-down as
        it lies at the skills' own yaw and held in the collision checker, taken to where the plan puts it -- the
        place its poses were taught at, above it, then down on it -- with the fixture now lying there as it does.
        The kind is the IK's at the first pose that fails (the tutorial's base on its side: the held peg goes into
        the base, ``collision``, on the Baxter and the Panda alike)."""
        import pinocchio as pin

        places = [target for target, (owner, _) in zip(self.targets, self.target_features, strict=True)
                  if owner == name]
        carried = sorted((p for p in self.grasped if p != name and p in world.sim.object_names()),
                         key=lambda p: self._step_of(p) if self._step_of(p) is not None else len(self.plan))
        if not places or not carried:
            return None
        part, target = carried[0], places[0]
        grasp = self._skills_grasp(world, part)
        poses = self._placing(world, part, grasp, target)
        arm = world.default_arm
        q = world.current_q()
        world.allow_hand(part, arm, True, preshape=False)
        pieces = [p for p in world.collision.objects if world.contact_object(p) == part]
        saved = {p: world.collision.pose(p) for p in pieces}
        try:
            q_grasp = world.ik.solve(arm, pin.SE3(grasp[:3, :3], grasp[:3, 3]), q, seed=0,
                                     check_collisions=False)
            if not q_grasp.success:
                return None  # not graspable: the grasp checks say so
            for piece in pieces:
                world.collision.attach(piece, world.end_effector(arm), q_grasp.q, allow=world.hand_links(arm))
            blocked = self._first_blocked(world, poses, q_grasp.q, target)
            return None if blocked is None else (
                blocked[0], f"{part}, carried where the plan puts it onto {name}, {blocked[1]}")
        finally:
            for piece in pieces:
                world.collision.detach(piece, pose=saved[piece])
            world.allow_hand(part, arm, False)

    def _feature_arrival(self, world: Any, name: str, owner: str, feature: str | None,
                         check_collisions: bool = True) -> bool:
        """Whether ``name``, grasped top-down as it lies (at one of :data:`GRASP_TURNS`), can be held with its
        primary feature on ``owner``'s ``feature`` (normals opposed, 2 mm apart) at one of :data:`ARRIVAL_YAWS`
        about the feature's normal: an IK solution clear of the scene for the gripper there (the part itself not
        carried in the check); ``check_collisions`` false: any IK solution, through obstacles or not."""
        import pinocchio as pin

        sim = world.sim
        part = sim.object_transform(name)
        primary = sim.object_model(name).feature(None)
        point_f, normal_f = np.asarray(primary.point, dtype=float), np.asarray(primary.normal, dtype=float)
        target, target_normal = (np.asarray(v, dtype=float) for v in sim.feature(owner, feature))
        align = _rotation_onto(normal_f, -target_normal)
        q0 = world.current_q()
        kept = self._grasp_turn.get(name)
        world.allow_hand(name, world.default_arm, True, preshape=False)
        try:
            for turn in GRASP_TURNS:
                self._grasp_turn[name] = math.radians(turn)
                in_gripper = np.linalg.inv(self._grasp(world, name)) @ part  # the part in the hand
                for yaw in ARRIVAL_YAWS:
                    goal = np.eye(4)
                    goal[:3, :3] = _axis_rotation(target_normal, math.radians(yaw)) @ align
                    goal[:3, 3] = target + 0.002 * target_normal - goal[:3, :3] @ point_f
                    gripper = goal @ np.linalg.inv(in_gripper)
                    target_se3 = pin.SE3(gripper[:3, :3], gripper[:3, 3])
                    if world.ik.solve(world.default_arm, target_se3, q0, seed=0,
                                      check_collisions=check_collisions).success:
                        return True
        finally:
            world.allow_hand(name, world.default_arm, False)
            if kept is None:
                self._grasp_turn.pop(name, None)
            else:
                self._grasp_turn[name] = kept
        return False

    def _stand_ins(self, world: Any, present: dict[str, Any], feasible: dict[str, tuple[bool, str | None, str]]
                   ) -> set[str]:
        """Letters: the blocks the task does not name that can stand in for its missing ones. The goal is judged by
        the cells occupied (any block of the shape fills a cell), so a free block of a missing block's shape is one
        the domain's place can put at that block's cell -- whether or not the named blocks could also tile the
        letter another way (letters_H s11 0008: b3 missing, b7 a 1x2, a green 1x1 lying on b4's cell is taken for
        b3 and the letter is drawn). For each missing block (by name) one of its shape, of its colour first where
        the task's symbols name colours, then one lying on a letter cell, then by name. The plan picks them up, so
        a cell one lies on is not occupied -- when that cell is filled after the missing block's step, which is
        where the stand-in is taken (letters_A s0 0101: a green 1x1 on b3's cell stands in for the missing b0)."""
        if not self.on_cells:
            return set()
        unnamed = sorted(n for n, m in present.items() if n not in self.needed and n not in self._supports()
                         and m.shape in ("1x1", "1x2"))
        occupied = {n: label.evidence["step"] for n in unnamed if (label := self._occupied_cell(world, [n]))}
        taken: set[str] = set()
        cleared: set[str] = set()
        for name in sorted(n for n in self.needed if n not in present):
            nominal = self.nominal.get(name)
            colour = nominal.colour if nominal is not None and name in self.colour_symbols else None
            fits = [n for n in unnamed if n not in taken and present[n].shape == self.shapes.get(name)
                    and feasible.get(n, (True,))[0]]  # one the robot can pick up
            if not fits:
                continue
            best = min(fits, key=lambda n: (colour is not None and present[n].colour != colour, n not in occupied, n))
            taken.add(best)
            if best not in occupied or occupied[best] >= (self._step_of(name) or 0):
                cleared.add(best)
        return cleared

    def _step_of(self, name: str) -> int | None:
        """The first step of the nominal plan whose arguments name ``name``."""
        return next((i for i, action in enumerate(self.plan) if name in map(str, action.args)), None)

    def _target_steps(self) -> dict[int, int]:
        """Index in :attr:`targets` -> the plan step that puts something there (letters: a place per cell)."""
        out: dict[int, int] = {}
        for step, action in enumerate(self.plan):
            if action.name in self.cell_actions:
                for _ in _cell_offsets(self.shapes.get(action.args[0])):
                    out[len(out)] = step
        return out if len(out) == len(self.targets) else {}

    def _grasp_at(self, world: Any, name: str) -> tuple[bool, str | None, str]:
        """(ok, failure kind, message) of the approach and the top-down grasp of ``name`` at its current grasp yaw."""
        import pinocchio as pin

        q = world.current_q()
        for allowed in (False, True):  # the approach over it, then the grasp, the fingers opened around it
            target = self._grasp(world, name) if allowed else self._over(world, name, APPROACH_HEIGHT)
            if allowed:
                q = self._open_around(world, name, q)
            world.allow_hand(name, world.default_arm, allowed, preshape=False)
            try:
                result = world.ik.solve(world.default_arm, pin.SE3(target[:3, :3], target[:3, 3]), q, seed=0)
                if result.success and allowed and world.sim.obstacles():  # the descent, against obstacles
                    hit = self._move_hit(world, q, result.q, target)
                    if hit is not None:
                        return False, "collision", f"{name}: the descent to the grasp runs into {hit}"
            finally:
                world.allow_hand(name, world.default_arm, False)
            if not result.success:
                return False, result.kind, f"{name}: {result.message}"
            q = result.q
        return True, None, ""

    def _graspable(self, world: Any, name: str) -> tuple[bool, str | None, str]:
        """(ok, failure kind, message) of a top-down grasp and its approach above ``name``: the robot reaches the
        part when some grasp yaw about the vertical (the skills' own first, then :data:`GRASP_TURNS` from it) has an
        IK solution clear of the scene -- a pose the domain's move primitive can be given, whichever yaw today's
        skills would pick. The failure reported is the skills' own yaw's."""
        transform = world.sim.object_transform(name)
        first: tuple[bool, str | None, str] | None = None
        for turn in GRASP_TURNS:
            self._grasp_turn[name] = math.radians(turn)
            outcome = self._grasp_at(world, name)
            if outcome[0]:
                break
            first = first or outcome
        else:
            self._grasp_turn.pop(name, None)
            return first  # type: ignore[return-value]
        if self.on_cells and _angle(_up(transform), np.array([0.0, 0.0, 1.0])) > UP_TOLERANCE:
            # A block on another face is turned where it lies before it is placed (the place skill keeps the
            # tilt in the gripper): the turn the skill would make from that grasp, lifted, must be reachable.
            from bt_meta.world.skills.place import turned_pose

            grasp = self._grasp(world, name)
            lifted = grasp.copy()
            lifted[2, 3] += APPROACH_HEIGHT
            if not turned_pose(world, name, world.default_arm, lifted, np.linalg.inv(grasp) @ transform)[1]:
                return False, "reachability", f"{name}: the turn that stands it on its base is out of reach"
        return True, None, ""

    # -- obstacles --------------------------------------------------------------------------------------------

    def _obstacle_label(self, world: Any, roles: dict[str, list[str]], feasible: dict[str, tuple[bool, str | None,
                        str]], present: dict[str, Any]) -> Label | None:
        """``limit:collision`` / ``repairable`` when static obstacles are in the way of the pick-and-places."""
        q0 = world.current_q()
        hit = self._hit(world, q0)
        if hit is not None:
            return Label("limit:collision", f"the robot's start configuration runs into {hit}",
                         {"contact": hit, "step": -1})
        stand_in = None
        place_steps = [i for i, action in enumerate(self.plan) if action.name in self.cell_actions]
        letters = self.on_cells and len(place_steps) == len(self.jobs)
        for index, (nominal, target) in enumerate(self.jobs):
            if self.on_cells:
                shape = present[nominal].shape if nominal in present else self.shapes.get(str(nominal))
                pool = [n for n in roles["blocks"] if present[n].shape == shape] or list(roles["blocks"])
            else:
                pool = list(roles.get(str(nominal), ()))
            pool = sorted(pool, key=lambda n: n != nominal)
            usable = [n for n in pool if feasible.get(n, (False, None, ""))[0]][:CANDIDATES]
            messages = []
            for name in usable:
                message = self._carry_hit(world, name, target, q0)
                if message is None:
                    break
                messages.append(message)
            else:
                if messages:
                    return Label("limit:collision", f"nothing can be put at ({target[0]:.3f}, {target[1]:.3f}) "
                                 f"clear of the obstacles: {messages[0]}",
                                 {"target": list(target[:2]), "step": place_steps[index] if letters else None})
                continue
            if messages and usable[0] == nominal and stand_in is None:
                stand_in = Label("repairable", f"{messages[0]}; another object gets there clear of the obstacles",
                                 {"object": nominal, "target": list(target[:2])})
        return stand_in

    def _hit(self, world: Any, q: np.ndarray) -> str | None:
        """The first contact of configuration ``q`` (and what the robot carries) with a static obstacle."""
        obstacles = set(world.sim.obstacles())
        for contact in world.collision.all_contacts(q):
            if world.contact_object(contact.first) in obstacles or world.contact_object(contact.second) in obstacles:
                return str(contact)
        return None

    def _path_hit(self, world: Any, q_from: np.ndarray, q_to: np.ndarray) -> str | None:
        """The first obstacle contact on the joint-space line from ``q_from`` to ``q_to``."""
        for k in range(1, PATH_STEPS + 1):
            hit = self._hit(world, q_from + (q_to - q_from) * (k / PATH_STEPS))
            if hit is not None:
                return hit
        return None

    def _line_hit(self, world: Any, q_from: np.ndarray, start: np.ndarray, goal: np.ndarray) -> str | None:
        """The first obstacle contact (or no solution) along the gripper's straight line from ``start`` to
        ``goal`` (4x4 poses), each waypoint solved from the one before, as move_to's fallback does."""
        import pinocchio as pin

        rotation = pin.log3(start[:3, :3].T @ goal[:3, :3])
        steps = max(PATH_STEPS, math.ceil(float(np.linalg.norm(goal[:3, 3] - start[:3, 3])) / 0.01))
        q = q_from
        for k in range(1, steps + 1):
            f = k / steps
            pose = pin.SE3(start[:3, :3] @ pin.exp3(rotation * f), start[:3, 3] + (goal[:3, 3] - start[:3, 3]) * f)
            result = world.ik.solve(world.default_arm, pose, q, seed=0, check_collisions=False)
            if not result.success:
                return f"no solution on the straight line ({result.message})"
            q = result.q
            hit = self._hit(world, q)
            if hit is not None:
                return hit
        return None

    def _lift_first_hit(self, world: Any, q_from: np.ndarray, start: np.ndarray, goal: np.ndarray,
                        q_goal: np.ndarray, clearance: float = 0.06) -> str | None:
        """move_to's second fallback: straight up by ``clearance`` (or to the goal's height), then the joint-space
        line to ``q_goal``; the first obstacle contact or failure, or None."""
        top = start.copy()
        top[2, 3] += max(clearance, float(goal[2, 3] - start[2, 3]))
        hit = self._line_hit(world, q_from, start, top)
        if hit is not None:
            return hit
        q_top, why = self._solve(world, top, q_from)
        if q_top is None:
            return why
        return self._path_hit(world, q_top, q_goal)

    def _move_hit(self, world: Any, q_from: np.ndarray, q_to: np.ndarray, goal: np.ndarray) -> str | None:
        """move_to's ways from ``q_from`` to ``q_to`` (the IK solution for gripper pose ``goal``), in its order: the
        joint-space line, the gripper's straight line, a lift first, a path planned around
        (:func:`~bt_meta.world.kinematics.path_planning.plan_path`, the skill's seed and budget). The joint line's
        obstacle contact when every way runs into an obstacle, else None."""
        from bt_meta.world.kinematics.forward import pose_matrix
        from bt_meta.world.kinematics.path_planning import plan_path

        hit = self._path_hit(world, q_from, q_to)
        if hit is None:
            return None
        start = pose_matrix(world.kin.end_effector_pose(q_from, world.default_arm))
        if self._line_hit(world, q_from, start, goal) is None:
            return None
        if self._lift_first_hit(world, q_from, start, goal, q_to) is None:
            return None
        indices = world.kin.arm_indices(world.default_arm)

        def free(arm_q: np.ndarray) -> bool:
            q = q_from.copy()
            q[indices] = arm_q
            return self._hit(world, q) is None

        path = plan_path(free, q_from[indices], q_to[indices], world.kin.lower[indices], world.kin.upper[indices],
                         seed=0)
        return hit if path is None else None

    def _solve(self, world: Any, pose: np.ndarray, q: np.ndarray) -> tuple[np.ndarray | None, str | None]:
        """IK for a gripper pose: a collision-free solution, else (when only other objects are in the way, which the
        skills allow for) the unchecked one if it clears the obstacles. (q, the obstacle contact or failure)."""
        import pinocchio as pin

        target = pin.SE3(pose[:3, :3], pose[:3, 3])
        result = world.ik.solve(world.default_arm, target, q, seed=0)
        if result.success:
            return result.q, None
        free = world.ik.solve(world.default_arm, target, q, seed=0, check_collisions=False)
        if not free.success:
            return None, f"no IK solution ({free.message})"
        hit = self._hit(world, free.q)
        return (free.q, None) if hit is None else (None, hit)

    def _carry_hit(self, world: Any, name: str, target: tuple[float, float, float], q0: np.ndarray) -> str | None:
        """Why ``name`` cannot be picked up and put at ``target`` clear of the obstacles, or None."""
        from bt_meta.world.kinematics.forward import pose_matrix

        transform = world.sim.object_transform(name)
        above, grasp = self._over(world, name, APPROACH_HEIGHT), self._grasp(world, name)
        world.allow_hand(name, world.default_arm, True, preshape=False)
        try:
            q1, why = self._motion(world, q0, above, f"reaching above {name}", f"reaching for {name}")
            if q1 is None:
                return why
            q2, why = self._solve(world, grasp, self._open_around(world, name, q1))
            if q2 is None:
                return f"grasping {name}: {why}"
            parts = [p for p in world.collision.objects if world.contact_object(p) == name]
            saved = {p: world.collision.pose(p) for p in parts}
            hand = world.hand_links(world.default_arm)
            for part in parts:
                world.collision.attach(part, world.end_effector(world.default_arm), q2, allow=hand)
            try:
                lifted = grasp.copy()
                lifted[2, 3] += APPROACH_HEIGHT
                q3, why = self._motion(world, q2, lifted, f"lifting {name}", f"lifting {name}")
                if q3 is None:
                    return why
                first = None
                attached = np.linalg.inv(grasp) @ transform
                gripper = pose_matrix(world.kin.end_effector_pose(q2, world.default_arm))
                for held, block in self._arrivals(world, name, attached, target):
                    if held is not attached:  # carried as another grasp holds it: move the parts to match
                        moved = gripper @ held @ np.linalg.inv(attached) @ np.linalg.inv(gripper)
                        for part in parts:
                            now = world.collision.pose(part, q2).homogeneous
                            world.collision.detach(part, pose=moved @ now)
                            world.collision.attach(part, world.end_effector(world.default_arm), q2, allow=hand)
                        attached = held
                    why = self._put_down_hit(world, name, target, q3, block @ np.linalg.inv(held))
                    if why is None:
                        return None
                    first = first or why
                return first
            finally:
                for part in parts:
                    world.collision.detach(part, pose=saved[part])
        finally:
            world.allow_hand(name, world.default_arm, False)

    def _arrivals(self, world: Any, name: str, as_grasped: np.ndarray, target: tuple[float, float, float]
                  ) -> list[tuple[np.ndarray, np.ndarray]]:
        """The ways ``name`` can arrive at ``target``: (the part in the gripper's frame, the part's pose there).

        As grasped where it lies, set down upright (the nominal plan's pose). A part turned off its nominal up axis
        (not a letters block: the place skill's turn handles those) has two more, the two repairs of such a part:
        held as the demonstrations grasp it, which a re-orientation gives when the task has ``Reorient...`` methods
        (it sets the part down on another face and picks it again), and held as it lies, its tilt kept at the
        target (pose backtracking's poses through the current grasp)."""
        from bt_meta.world.simulation.objects import pose_to_matrix
        from bt_meta.world.skills.place import nearest_yaw, object_yaw, symmetry

        transform = world.sim.object_transform(name)
        model = world.sim.object_model(name)
        goal_yaw = nearest_yaw(object_yaw(transform), symmetry(model), object_yaw(transform))
        upright = pose_to_matrix((target[0], target[1], target[2] + model.lowest_z(0.0, 0.0) + 0.002,
                                  0.0, 0.0, goal_yaw))
        out = [(as_grasped, upright)]
        nominal_up = self.nominal_up.get(name, np.array([0.0, 0.0, 1.0]))
        if self.on_cells or _angle(_up(transform), nominal_up) <= UP_TOLERANCE:
            return out
        demonstrated = self.nominal_held.get(model.type)
        if demonstrated is not None and self.reorientable:
            out.append((demonstrated, upright))
        tilted = transform.copy()
        lowest = float(-(model.points() @ transform[:3, :3].T)[:, 2].min())
        tilted[:3, 3] = (target[0], target[1], target[2] + lowest + 0.002)
        out.append((as_grasped, tilted))
        return out

    def _put_down_hit(self, world: Any, name: str, target: tuple[float, float, float], q_lifted: np.ndarray,
                      down: np.ndarray) -> str | None:
        """Why the held ``name`` cannot be carried over ``target`` and lowered to gripper pose ``down``, or None."""
        over = down.copy()
        over[2, 3] += APPROACH_HEIGHT
        at = f"({target[0]:.3f}, {target[1]:.3f})"
        q4, why = self._motion(world, q_lifted, over, f"carrying {name} over {at}", f"carrying {name} to {at}")
        if q4 is None:
            return why
        return self._motion(world, q4, down, f"lowering {name} at {at}", f"lowering {name} at {at}")[1]

    def _motion(self, world: Any, q_from: np.ndarray, pose: np.ndarray, solving: str, moving: str
                ) -> tuple[np.ndarray | None, str | None]:
        """The move from ``q_from`` to gripper ``pose``: (its goal configuration, None), or (None, why not: no
        solution while ``solving``, or an obstacle in the way while ``moving``)."""
        q, why = self._solve(world, pose, q_from)
        if q is None:
            return None, f"{solving}: {why}"
        if (hit := self._move_hit(world, q_from, q, pose)) is not None:
            return None, f"{moving} runs into {hit}"
        return q, None

    def _fill(self, roles: dict[str, list[str]], feasible: dict[str, tuple[bool, str | None, str]],
              present: dict[str, Any]) -> Label | None:
        """A limit label when some role has no candidate the robot can grasp."""
        def limit(names: Iterable[str]) -> Label:
            names = list(names)
            kinds = [feasible[n][1] for n in names if not feasible[n][0]]
            kind = "reachability" if "reachability" in kinds else "collision"
            message = next((feasible[n][2] for n in names if feasible[n][1] == kind), "")
            first = [self._step_of(n) for n in names if not feasible[n][0] and self._step_of(n) is not None]
            return Label(f"limit:{kind}", f"no graspable object: {message}",
                         {"kind": kind, "step": min(first) if first else None})

        if self.on_cells:
            ok = [n for n in roles["blocks"] if feasible[n][0]]
            n1 = sum(present[n].shape == "1x1" for n in ok)
            n2 = sum(present[n].shape == "1x2" for n in ok)
            if not letters_feasible(len(self.cells), max_pairs(self.cells), n1, n2):
                # the run stops at the first needed block it cannot grasp (a stand-in covers no cell more)
                bad = [n for n in self.needed if n in feasible and not feasible[n][0]]
                return limit([*bad, *(n for n in roles["blocks"] if n not in bad)])
            needed_bad = [n for n in self.needed if n in feasible and not feasible[n][0]]
            spare_ok = any(feasible[n][0] for n in roles["blocks"] if n not in self.needed)
            if needed_bad and not spare_ok:
                return limit(needed_bad)
            return None
        for candidates in roles.values():
            if not any(feasible[n][0] for n in candidates):
                return limit(candidates)
        return None


def _rotation_onto(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis, cos = np.cross(a, b), float(np.dot(a, b))
    if np.linalg.norm(axis) < 1e-9:
        if cos > 0:
            return np.eye(3)
        other = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        return _axis_rotation(np.cross(a, other), math.pi)
    return _axis_rotation(axis, math.atan2(float(np.linalg.norm(axis)), cos))


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: the rotation by ``angle`` about ``axis``."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


def _up(transform: np.ndarray) -> np.ndarray:
    return np.asarray(transform[:3, 2], dtype=float)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(math.acos(max(-1.0, min(1.0, float(np.dot(a, b)) / (np.linalg.norm(a) * np.linalg.norm(b))))))
