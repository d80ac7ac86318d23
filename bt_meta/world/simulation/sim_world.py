"""SimWorld: the :class:`~bt_meta.world.base.World` of a task file's problem in the pybullet simulator.

A SimWorld owns a :class:`~bt_meta.world.simulation.sim.Simulation` with the problem's scene (and variant) built in
it, the robot's kinematics, a collision checker whose scene mirrors the simulator's objects, and mink IK. HTN primitives
map onto skills (:mod:`bt_meta.world.skills`) through a **grounding file** -- data, not code: ``poses/<domain>.yaml``
next to the task file or in the shipped ``trees/poses/``. It says, per problem, which scene and variant to build;
per primitive, which skill runs it; how the task file's symbols become numbers (letter cells in lb from a scene
anchor, named gripper poses).

Symbolic state: the problem's initial facts, updated by the add/delete effects of every primitive whose skill
succeeded (the world does not re-derive facts from poses; perception plugins compare it with the object states).

Offers:

* :class:`SimWorld` -- the world; :meth:`SimWorld.from_task_file` builds it from a file, a problem, a variant, a seed;
  what skills ask of it includes where a top-down grasp goes (:meth:`SimWorld.grasp_xy`: a catalogue grasp frame
  pointing down, else the centroid) and how deep (:meth:`SimWorld.grasp_height`: a friction grasp's pads on the
  part's widest band)
* :class:`Grounding` / :func:`load_grounding` -- the grounding file
* :class:`PrimitiveSkill` -- a skill run for a primitive: applies the primitive's effects on success
* :func:`quiet_stdout` -- silences what pybullet prints on the C level (keeps ``--json`` output clean)
* :func:`pose_symbol` / :func:`parse_pose_symbol` -- durable pose symbols (``pose:x:y:z:roll:pitch:yaw``, metres and
  radians) that a repair creates and a learned refinement stores; the world grounds them without a grounding-file
  entry (:meth:`SimWorld.register_pose` also gives them their type fact ``pose(symbol)``)
* :func:`held_pose_symbol` / :func:`parse_held_pose_symbol` -- durable poses of the *held object* relative to
  another object (``held:OBJECT:x:y:z:roll:pitch:yaw``, the held object's pose in OBJECT's frame): grounded through
  the grasp at the time of the move, so they stay right when OBJECT has moved or the part was grasped differently
* :func:`bt_meta_make_world` -- hook implementation for ``--world sim`` (register this module as a plugin)
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import sys
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from bt_meta._stdio import flush_c_stdio
from bt_meta.bt.failures import FailureKind
from bt_meta.errors import BtMetaError, ConfigError
from bt_meta.hookspecs import hookimpl
from bt_meta.htn.state import State
from bt_meta.resources import trees_dir
from bt_meta.world.base import FAILURE, SUCCESS, Atom, SkillFailure, ground_effects
from bt_meta.world.kinematics.collision import SHRINK
from bt_meta.world.poses import axis_angle_matrix
from bt_meta.world.robot.description import available_robots
from bt_meta.world.simulation.objects import Box, Cylinder, Mesh, ObjectModel, pose_to_matrix, rpy_to_matrix
from bt_meta.world.simulation.sections import Section, square_contact, widest_section
from bt_meta.world.skills import SKILLS
from bt_meta.world.skills.base import SimSkill, SkillAbort
from bt_meta.world.symmetry import yaw_period

__all__ = ["HELD_POSE_PREFIX", "POSE_SYMBOL_PREFIX", "Grounding", "PrimitiveSkill", "SimWorld", "held_pose_symbol",
           "load_grounding", "parse_held_pose_symbol", "parse_pose_symbol", "pose_symbol", "quiet_stdout"]

_PART = "~"  # collision geometry names: "<object>" for the first part, "<object>~<k>" for the others

POSE_SYMBOL_PREFIX = "pose:"
HELD_POSE_PREFIX = "held:"


UNTURNED = math.radians(1.0)
"""rad: a part turned less than this about the vertical from its scene frame is grasped as if unturned."""
SQUARE_CONTACT = 0.003
"""A friction grasp's pads must meet faces square to them over at least this height (m), else they are on a slope
or an edge (:func:`~bt_meta.world.simulation.sections.square_contact`) and go to the section's widest band."""


def pose_symbol(pose: Sequence[float], digits: int = 4) -> str:
    """A durable symbol for a gripper pose (x, y, z in metres, roll, pitch, yaw in radians): it names the pose
    itself, so a plan that stores it (a learned refinement) is grounded again by any later world."""
    values = [float(v) for v in pose]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise BtMetaError(f"a pose symbol needs 6 finite numbers, got {list(pose)}")
    texts = []
    for value in values:
        text = f"{round(value, digits):.{digits}f}".rstrip("0").rstrip(".")
        texts.append("0" if text in ("-0", "") else text)
    return POSE_SYMBOL_PREFIX + ":".join(texts)


def parse_pose_symbol(symbol: str) -> list[float] | None:
    """The 6 numbers of a :func:`pose_symbol`, or ``None`` when ``symbol`` is not one."""
    if not symbol.startswith(POSE_SYMBOL_PREFIX):
        return None
    parts = symbol[len(POSE_SYMBOL_PREFIX):].split(":")
    if len(parts) != 6:
        return None
    try:
        values = [float(p) for p in parts]
    except ValueError:
        return None
    return values if all(math.isfinite(v) for v in values) else None


def held_pose_symbol(relative_to: str, pose: Sequence[float], digits: int = 4) -> str:
    """A durable symbol for "the held object at ``pose`` in ``relative_to``'s frame" (x, y, z in metres, roll,
    pitch, yaw in radians); ``relative_to`` is a task-file object symbol or a world object name."""
    if not relative_to or ":" in relative_to:
        raise BtMetaError(f"a held-pose symbol needs an object name without ':', got {relative_to!r}")
    return HELD_POSE_PREFIX + relative_to + ":" + pose_symbol(pose, digits)[len(POSE_SYMBOL_PREFIX):]


def parse_held_pose_symbol(symbol: str) -> tuple[str, list[float]] | None:
    """(object, 6 numbers) of a :func:`held_pose_symbol`, or ``None`` when ``symbol`` is not one."""
    if not symbol.startswith(HELD_POSE_PREFIX):
        return None
    name, _, rest = symbol[len(HELD_POSE_PREFIX):].partition(":")
    values = parse_pose_symbol(POSE_SYMBOL_PREFIX + rest) if name else None
    return None if values is None else (name, values)


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Send file descriptor 1 to /dev/null (pybullet's C code prints build info and URDF warnings there)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        sys.stdout.flush()
        flush_c_stdio()  # pybullet's printf text, while fd 1 still points at /dev/null
        os.dup2(saved, fd)
        os.close(saved)


# --------------------------------------------------------------------------------------------------------------
# The grounding file


@dataclass(frozen=True)
class Grounding:
    """What a grounding file says (see the module docstring and ``trees/poses/*.yaml``)."""

    path: Path
    domain: str
    problems: dict[str, dict[str, Any]]
    skills: dict[str, dict[str, Any]]
    frames: dict[str, dict[str, Any]] = field(default_factory=dict)
    poses: dict[str, dict[str, Any]] = field(default_factory=dict)
    robot_pose: dict[str, dict[str, float]] = field(default_factory=dict)
    """Robot name (``"*"``: any robot) -> joint values (radians) that replace its home pose at the start, e.g. the
    idle arm parked. See :meth:`start_pose`."""
    objects: dict[str, str] = field(default_factory=dict)
    """Task-file object symbol -> simulator object name, where they differ."""
    features: dict[str, dict[str, str]] = field(default_factory=dict)
    """Task-file feature symbol -> ``{object, feature}`` (an attachment feature of a simulator object)."""
    robot: str | None = None
    """The robot the problems run on unless the caller chooses one: a shipped name or a path (resolved against
    the grounding file's folder)."""
    anchor_uses: tuple[tuple[str, str, int | None, int | None], ...] = ()
    """Every scene anchor the file names: (anchor, where -- ``poses.turn_high`` --, line, column), so a scene
    without one is refused when the world is built, at the line that names it (:meth:`check_anchors`)."""

    def check_anchors(self, scene: Any) -> None:
        """Raise :class:`ConfigError` at the first line naming an anchor ``scene`` lacks (before any motion)."""
        anchors = getattr(scene, "anchors", {}) or {}
        for anchor, where, line, column in self.anchor_uses:
            if anchor not in anchors:
                known = ", ".join(anchors) or "none"
                raise ConfigError(f"{where} names anchor {anchor!r}, which scene {scene.name!r} ({scene.path}) "
                                  f"does not have; its anchors: {known}", self.path, line, column)

    def start_pose(self, robot: str) -> dict[str, float]:
        """Joint values replacing ``robot``'s home pose at the start: the file's ``robot_pose`` for that robot."""
        return {**self.robot_pose.get("*", {}), **self.robot_pose.get(robot, {})}

    def problem(self, name: str) -> dict[str, Any]:
        try:
            return self.problems[name]
        except KeyError:
            known = ", ".join(self.problems) or "none"
            raise ConfigError(f"the grounding file has no problem {name!r}; problems: {known}", self.path) from None


_TOP_KEYS = {"domain", "problems", "skills", "frames", "poses", "robot_pose", "objects", "features", "description",
             "robot"}


def grounding_paths(domain: str, task_file: str | Path | None = None) -> list[Path]:
    """Where the grounding file of ``domain`` is looked for, in order."""
    paths = []
    if task_file is not None:
        paths.append(Path(task_file).parent / "poses" / f"{domain}.yaml")
    paths.append(trees_dir() / "poses" / f"{domain}.yaml")
    return paths


def load_grounding(domain: str, task_file: str | Path | None = None, path: str | Path | None = None) -> Grounding:
    """The grounding of ``domain``: ``path`` if given, else ``poses/<domain>.yaml`` beside the task file or shipped."""
    if path is None:
        candidates = grounding_paths(domain, task_file)
        found = next((p for p in candidates if p.is_file()), None)
        if found is None:
            raise ConfigError(f"no grounding file for domain {domain!r} (looked for "
                              f"{', '.join(str(p) for p in candidates)}): the simulator cannot run its primitives")
        path = found
    path = Path(path)
    from bt_meta.safe_yaml import load_yaml
    from bt_meta.user_files import read_user_text

    text = read_user_text(path, what="grounding file", error=ConfigError)
    data = load_yaml(text, str(path), ConfigError, syntax="not valid YAML")
    if not isinstance(data, dict):
        raise ConfigError("a grounding file is a mapping", path, 1, 1)
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ConfigError(f"unknown keys {sorted(unknown)}; expected {sorted(_TOP_KEYS)}", path)
    for key in ("problems", "skills"):
        if not isinstance(data.get(key), dict) or not data[key]:
            raise ConfigError(f"{key!r} must be a non-empty mapping", path)
    for primitive, spec in data["skills"].items():
        if not isinstance(spec, dict) or spec.get("skill") not in SKILLS:
            raise ConfigError(f"skills.{primitive}: give `skill:` one of {', '.join(SKILLS)}", path)
    robot = data.get("robot")
    if robot is not None:
        if not isinstance(robot, str) or not robot:
            raise ConfigError(f"`robot:` names a shipped robot ({', '.join(available_robots())}) or a robot "
                              "description file", path)
        if robot.endswith((".yaml", ".yml")):
            robot = str(path.parent / robot)
    for key in ("problems", "frames", "poses", "features"):
        _mapping_of_mappings(data, key, path)
    for symbol, spec in (data.get("poses") or {}).items():
        numbers = spec.get("pose")
        if numbers is not None and (not isinstance(numbers, list) or len(numbers) not in (3, 6)
                                    or not all(isinstance(v, (int, float)) for v in numbers)):
            line, column = _position_in(path, ("poses", str(symbol), "pose"))
            raise ConfigError(f"pose {symbol!r}: give [x, y, z] (pointing down as the robot grasps) or "
                              f"[x, y, z, roll, pitch, yaw] (metres, degrees), not {numbers!r}", path, line, column)
    objects = {str(k): str(v) for k, v in _mapping_of_scalars(data, "objects", path).items()}
    return Grounding(path, str(data.get("domain", domain)), dict(data["problems"]), dict(data["skills"]),
                     dict(data.get("frames") or {}), dict(data.get("poses") or {}),
                     _robot_poses(data.get("robot_pose"), path), objects,
                     {str(k): dict(v) for k, v in (data.get("features") or {}).items()}, robot,
                     _anchor_uses(text, path))


def _anchor_uses(text: str, path: Path) -> tuple[tuple[str, str, int | None, int | None], ...]:
    """Where the file names a scene anchor (``anchor:`` under ``frames`` and ``poses``), with its position."""
    from bt_meta.safe_yaml import compose_yaml

    root = compose_yaml(text, str(path), ConfigError, syntax="not valid YAML")  # the tree load_yaml composed
    uses: list[tuple[str, str, int | None, int | None]] = []
    for section, entries in _mapping_items(root):
        if section.value not in ("frames", "poses"):
            continue
        for name, spec in _mapping_items(entries):
            for key, value in _mapping_items(spec):
                if key.value == "anchor" and isinstance(value, yaml.ScalarNode):
                    mark = value.start_mark
                    uses.append((str(value.value), f"{section.value}.{name.value}", mark.line + 1, mark.column + 1))
    return tuple(uses)


def _mapping_items(node: Any) -> list[tuple[Any, Any]]:
    """A mapping node's (key, value) node pairs whose keys are scalars; nothing for any other node."""
    if not isinstance(node, yaml.MappingNode):
        return []
    return [(k, v) for k, v in node.value if isinstance(k, yaml.ScalarNode)]


def _robot_poses(value: Any, path: Path) -> dict[str, dict[str, float]]:
    """``robot_pose:`` is joint -> value (any robot) or robot name -> {joint: value} (joints differ per robot)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError("robot_pose is a mapping: joint -> value, or robot name -> {joint: value}", path)
    per_robot = [isinstance(v, dict) for v in value.values()]
    if any(per_robot) and not all(per_robot):
        raise ConfigError("robot_pose mixes joint values and per-robot mappings: use one form", path)
    blocks = value if all(per_robot) and per_robot else {"*": value}
    out: dict[str, dict[str, float]] = {}
    for robot, joints in blocks.items():
        try:
            out[str(robot)] = {str(k): float(v) for k, v in joints.items()}
        except (TypeError, ValueError):
            where = "robot_pose" if robot == "*" else f"robot_pose of {robot}"
            raise ConfigError(f"{where}: joint values are numbers (radians or metres)", path) from None
    return out


def _mapping_of_mappings(data: dict[str, Any], key: str, path: Path) -> None:
    value = data.get(key) or {}
    if not isinstance(value, dict) or not all(isinstance(item, dict) for item in value.values()):
        raise ConfigError(f"{key!r} must be a mapping of name -> mapping", path)


def _mapping_of_scalars(data: dict[str, Any], key: str, path: Path) -> dict[Any, Any]:
    value = data.get(key) or {}
    if not isinstance(value, dict) or any(isinstance(item, (dict, list)) for item in value.values()):
        raise ConfigError(f"{key!r} must be a mapping of name -> value", path)
    return value


# --------------------------------------------------------------------------------------------------------------
# The world


class PrimitiveSkill:
    """A skill run for an HTN primitive; on success the primitive's effects update the world's symbolic state."""

    def __init__(self, world: SimWorld, primitive: Any, skill: SimSkill) -> None:
        self.world = world
        self.primitive = primitive
        self.inner = skill
        self.args: tuple[str, ...] = ()
        self.effects: tuple[list[Atom], list[Atom]] | None = None
        self.wall_time = 0.0
        self._recorded = False

    @property
    def failure(self) -> SkillFailure | None:
        return self.inner.failure

    def start(self, args: Sequence[str], ctx: Any = None) -> None:
        self.args = tuple(str(a) for a in args)
        self.inner.start(self.args, ctx)

    def tick(self) -> str:
        started = time.perf_counter()
        status = self.inner.tick()
        self.wall_time += time.perf_counter() - started
        if status == SUCCESS and self.effects is None and self.primitive is not None:
            effects = ground_effects(self.primitive, self.args, self.world.symbolic_state())
            self.effects = effects or ([], [])
            if effects is not None:
                self.world.apply_symbolic(*effects)
        if status in (SUCCESS, FAILURE) and not self._recorded:
            self._recorded = True
            self.world.executed.append(self.record())
        return status

    def cancel(self) -> None:
        self.inner.cancel()

    def record(self) -> dict[str, Any]:
        out = {"action": None if self.primitive is None else self.primitive.name, **self.inner.record(),
               "args": list(self.args), "wall_ms": round(self.wall_time * 1000.0, 2)}
        if self.effects is not None:
            out["effects"] = {"add": [list(a) for a in self.effects[0]], "delete": [list(a) for a in self.effects[1]]}
        return out


class SimWorld:
    """A task-file problem acted out in pybullet (see the module docstring)."""

    def __init__(
        self,
        domain: Any,
        problem: Any,
        grounding: Grounding,
        *,
        variant: str | None = None,
        seed: int = 0,
        gui: bool = False,
        steps_per_tick: int = 12,
        joint_speed: float = 1.5,
        sim: Any = None,
        realtime: bool | None = None,
        robot: Any = None,
        scene: str | Path | None = None,
    ) -> None:
        from bt_meta.world.fake import initial_state
        from bt_meta.world.kinematics.collision import TABLE, CollisionChecker
        from bt_meta.world.kinematics.forward import Kinematics
        from bt_meta.world.kinematics.ik import InverseKinematics
        from bt_meta.world.simulation.scenes import load_scene

        self.domain = domain
        self.problem = problem
        self.grounding = grounding
        self.stand_ins: dict[str, str] = {}
        """Simulator objects stood in for since a rebinding: the demonstrated part's name -> its stand-in's."""
        self.seed = seed
        self._last_section: tuple[ObjectModel, tuple[Any, ...], Section | None] | None = None
        """The last :meth:`_section` asked for and its answer: a grasp pose's height and point both need it."""
        self.steps_per_tick = steps_per_tick
        self.joint_speed = joint_speed
        problem_name = getattr(problem, "name", None) or str(problem)
        setup = grounding.problem(problem_name)
        missing = sorted(set(domain.primitives) - set(grounding.skills))
        if missing:
            raise ConfigError(f"primitives without a skill in the grounding file: {', '.join(missing)}",
                              grounding.path)
        scene_name = scene if scene is not None else setup.get("scene")
        if not scene_name:
            raise ConfigError(f"problems.{problem_name}: give the `scene:` to build", grounding.path)
        if scene is None and str(scene_name).endswith((".yaml", ".yml")):
            scene_name = grounding.path.parent / str(scene_name)  # a path in the grounding file: beside it
        self.scene = load_scene(scene_name)
        grounding.check_anchors(self.scene)
        if variant is None:
            variant = setup.get("variant")
        if variant is not None and variant != "nominal" and variant not in self.scene.variants:
            known = ", ".join(["nominal", *self.scene.variants])
            raise ConfigError(f"scene {self.scene.name!r} has no variant {variant!r}; variants: {known}",
                              self.scene.path)
        self.variant = variant or "nominal"
        self._own_sim = sim is None
        if sim is None:
            from bt_meta.world.robot.description import RobotDescription, load_robot
            from bt_meta.world.simulation.sim import Simulation

            chosen = robot if robot is not None else grounding.robot or "baxter"
            description = chosen if isinstance(chosen, RobotDescription) else load_robot(chosen)
            with quiet_stdout():
                sim = Simulation(gui=gui, seed=seed, visuals="full" if gui else "light", robot=description)
        else:
            sim.clear_objects()
            for arm in sim.robot.arms:
                sim.release(arm)
        self.sim = sim
        self.realtime = gui if realtime is None else realtime
        self.tick_seconds = steps_per_tick * sim.time_step
        try:
            sim.set_joint_positions({**sim.robot.home, **self._start_pose(sim.robot, grounding)})
            self.scene.build(sim, None if self.variant == "nominal" else self.variant, seed=seed)
            self._check_objects(problem_name)
            self._check_supports()
        except BaseException:
            self.close()
            raise
        self.kin = Kinematics(sim.robot)
        self.collision = CollisionChecker(self.kin)
        self.ik = InverseKinematics(self.kin, self.collision)
        self._hand_links = {arm: self._arm_hand_links(arm) for arm in sim.robot.arms}
        self._geometry: dict[str, list[str]] = {}
        self._put_down_at: dict[str, tuple[str, float, tuple[float, float] | None]] = {}
        self._turned_at: dict[tuple[str, str], np.ndarray] = {}
        """(anchor, part) -> the gripper rotation of the last ``turn_up`` pose grounded there while holding it: let
        go, the gripper leaves as it held it (grounded from the part as it now lies, it would sweep through it)."""
        """Anchor -> the part last put down there, its footprint radius, the spot chosen (:meth:`_clear_of_others`)."""
        t = sim.table
        self.collision.add_box(TABLE, (t.size_x, t.size_y, t.thickness),
                               pose_to_matrix((t.center_x, t.center_y, t.top_z - t.thickness / 2.0, 0, 0, 0)))
        for name, (model, transform) in sim.obstacles().items():  # static: added once, never moved
            for k, (kind, dims, local) in enumerate(_collision_shapes(model)):
                part = name if k == 0 else f"{name}{_PART}{k}"
                self._add_shape(part, kind, dims, transform @ local)
                self.collision.fix(part)
        self.sync_collision()
        self._state = initial_state(problem)
        self.executed: list[dict[str, Any]] = []
        self.total_ticks = 0
        self.grasp_poses: dict[str, np.ndarray] = {}
        """Object -> the gripper pose (4x4, base frame) its last grasp closed at: where a skill that must let a
        block go as it was picked (a turn of a block carried tilted) takes it back to."""

    @staticmethod
    def _start_pose(robot: Any, grounding: Grounding) -> dict[str, float]:
        pose = grounding.start_pose(robot.name)
        unknown = sorted(set(pose) - set(robot.home))
        if unknown:
            raise ConfigError(f"robot_pose: robot {robot.name!r} has no joints {', '.join(unknown)}", grounding.path)
        return pose

    @property
    def default_arm(self) -> str:
        return str(self.sim.robot.default_arm)

    @classmethod
    def from_task_file(cls, path: str | Path, problem: str | None = None, *, variant: str | None = None,
                       seed: int = 0, gui: bool = False, grounding: str | Path | None = None,
                       **options: Any) -> SimWorld:
        from bt_meta.htn import load_task_file

        task_file = load_task_file(path)
        chosen = task_file.problem(problem)
        return cls(task_file.domain, chosen, load_grounding(task_file.domain.name, path, grounding),
                   variant=variant, seed=seed, gui=gui, **options)

    def close(self) -> None:
        if self._own_sim:
            self.sim.close()

    # -- World protocol -----------------------------------------------------------------------------------------

    def symbolic_state(self) -> State:
        return self._state

    def apply_symbolic(self, add: Iterable[Atom], delete: Iterable[Atom]) -> None:
        self._state = self._state.apply(add=add, delete=delete)

    def skill(self, action: str) -> PrimitiveSkill:
        spec = self.grounding.skills.get(action)
        if spec is None:
            raise BtMetaError(f"the simulator has no skill for {action!r}; grounded primitives: "
                              f"{', '.join(self.grounding.skills)} ({self.grounding.path})")
        skill = SKILLS[spec["skill"]](self, spec.get("arm", self.default_arm))
        skill.spec = spec
        return PrimitiveSkill(self, self.domain.primitives.get(action), skill)

    def observe(self) -> dict[str, Any]:
        return {
            "symbolic_state": self._state,
            "objects": {name: state.as_dict() for name, state in self.sim.object_states().items()},
            "held": {arm: self.sim.held(arm) for arm in self.sim.robot.arms},
            "attachments": [list(pair) for pair in self.sim.attachments()],
            "gripper": {arm: list(self.sim.gripper_pose(arm)) for arm in self.sim.robot.arms},
        }

    # -- what skills use ----------------------------------------------------------------------------------------

    def end_effector(self, arm: str) -> str:
        return self.sim.robot.arm(arm).end_effector

    def hand_links(self, arm: str) -> list[str]:
        """The robot links moved by ``arm``'s last joint: what a held object may touch without a collision."""
        return list(self._hand_links[arm])

    def current_q(self) -> np.ndarray:
        return self.kin.q_from_dict(self.sim.joint_positions(), self.kin.home)

    def drive_arm(self, arm: str, values: np.ndarray) -> None:
        joints = self.sim.robot.arm(arm).joints
        self.sim.set_joint_targets(dict(zip(joints, (float(v) for v in values), strict=True)))

    def advance(self, ticks: int = 1) -> None:
        """Run the physics for ``ticks`` ticks (the magnetic attach rule is checked at every physics step)."""
        self.sim.step(self.steps_per_tick * ticks)
        self.total_ticks += ticks
        if self.realtime:
            time.sleep(self.tick_seconds * ticks)

    def held_relative(self, arm: str) -> np.ndarray:
        """Pose of the held object in the gripper frame."""
        held = self.sim.held(arm)
        if held is None:
            raise BtMetaError(f"the {arm} gripper holds nothing")
        gripper = self.sim.link_transform(self.end_effector(arm))
        return np.linalg.inv(gripper) @ self.sim.object_transform(held)

    def grasp(self, name: str, arm: str, reach: float) -> bool:
        if not self.sim.grasp(name, arm, max_distance=reach):
            return False
        self.sync_collision()
        hand = self._hand_links[arm]
        for part in self._geometry.get(name, []):
            self.collision.attach(part, self.end_effector(arm), self.current_q(), allow=hand)
        return True

    def release(self, arm: str) -> str | None:
        name = self.sim.release(arm)
        if name is not None:
            q = self.current_q()
            for part in self._geometry.get(name, []):
                self.collision.detach(part, q=q)
        return name

    def allow_hand(self, name: str, arm: str, allowed: bool = True, preshape: bool = True) -> None:
        """Let the hand touch ``name`` in collision checks (approaching it to grasp), or stop letting it. Allowing
        it also opens a friction gripper's fingers just wider than ``name``, for the way down around it (not with
        ``preshape`` false: a check that must not move the fingers)."""
        if allowed and preshape and self.sim.held(arm) is None:
            self.sim.preshape(arm, name)
        for part in self._geometry.get(name, []):
            if allowed:
                self.collision.allow(part, self._hand_links[arm])
            else:
                self.collision.disallow(part)

    def grasp_xy(self, name: str, arm: str | None = None, rotation: np.ndarray | None = None) -> tuple[float, float]:
        """Where (base frame x, y) a top-down grasp of ``name`` goes: over the first of its type's catalogue grasp
        frames that points down as the object is turned now (within 30 degrees), else over its centroid (a part
        lying on another face than its frames were written for, a built-in type). Given the ``arm`` (and the
        gripper ``rotation`` it will grasp with; default: as the hand is turned now), a friction grasp whose fingers
        would close there on a narrower section than the part's widest goes over the widest instead
        (:func:`~bt_meta.world.simulation.sections.widest_section`: a housing lying on its side is held by its
        flange, as standing, not by the body beside it)."""
        if arm is not None:
            section = self._section(name, arm, rotation)
            if section is not None and section.moved:
                return section.x, section.y
        return self._grasp_frame_xy(name)

    def _section(self, name: str, arm: str, rotation: np.ndarray | None = None) -> Section | None:
        """The widest section of ``name`` across the fingers of ``arm``'s gripper held at ``rotation`` (default:
        as it is now), for a friction grasp; ``None`` for other grasps."""
        sim = self.sim
        if not sim.grasps_by_friction(name, arm):
            return None
        axis = self._fingers_now(arm, rotation)
        model, transform, at = sim.object_model(name), sim.object_transform(name), self._grasp_frame_xy(name)
        key = (transform.tobytes(), np.asarray(axis, float).tobytes(), at)
        last = self._last_section
        if last is None or last[0] is not model or last[1] != key:
            last = self._last_section = (model, key, widest_section(model, transform, axis, at))
        return last[2]

    def _fingers_now(self, arm: str, rotation: np.ndarray | None) -> np.ndarray:
        """The closing axis of ``arm``'s fingers at ``rotation`` (default: as the hand is turned now)."""
        return self.sim.closing_axis(arm) if rotation is None else self.fingers_axis(np.asarray(rotation), arm)

    def _grasp_frame_xy(self, name: str) -> tuple[float, float]:
        """Over the first catalogue grasp frame pointing down, else the centroid (:meth:`grasp_xy`)."""
        t = self.sim.object_transform(name)
        for frame in self.sim.object_model(name).grasp_frames():
            approach = t[:3, :3] @ rpy_to_matrix(*frame[3:])[:, 2]
            if float(approach[2]) <= -math.cos(math.radians(30.0)):
                point = t[:3, :3] @ np.asarray(frame[:3]) + t[:3, 3]
                return float(point[0]), float(point[1])
        return float(t[0, 3]), float(t[1, 3])

    def own_heading(self, name: str, arm: str) -> float:
        """How far (rad) ``name`` is turned about the vertical from its scene frame, up to the yaw period of its shape
        (:func:`~bt_meta.world.symmetry.yaw_period`), the turn nearest zero: a top-down grasp turned by it holds the
        part as it holds it unturned (so an asymmetric part still arrives along its target, and a parallel gripper
        closes on the faces it closes on unturned). Zero for a part lying on a side (its re-orientation turns it);
        for the part ``arm`` holds, the turn its top-down gripper has now (the part rides as it was grasped)."""
        if self.sim.held(arm) == name:
            g = self.sim.link_transform(self.end_effector(arm))
            if float(g[2, 2]) > -math.cos(math.radians(30.0)):  # not top-down: as the grounding says
                return 0.0
            turn = math.atan2(float(g[1, 0]), float(g[0, 0])) - self.sim.robot.arm(arm).top_down_yaw
            return math.atan2(math.sin(turn), math.cos(turn))
        t = self.sim.object_transform(name)
        if abs(float(t[2, 2])) < math.cos(math.radians(30.0)):
            return self._across_turn_axis(t, arm)
        period = yaw_period(self.sim.object_model(name))
        yaw = math.atan2(float(t[1, 0]), float(t[0, 0]))
        heading = yaw - period * round(yaw / period)
        # within a degree the part is as demonstrated: the grasp the traces and refinements were made with
        return 0.0 if abs(heading) < UNTURNED else heading

    def fingers_axis(self, rotation: np.ndarray, arm: str) -> np.ndarray:
        """The fingers' closing axis (base frame) of the arm's gripper held at ``rotation``."""
        now = self.sim.link_transform(self.end_effector(arm))[:3, :3]
        return rotation @ (now.T @ self.sim.closing_axis(arm))

    def _across_turn_axis(self, t: np.ndarray, arm: str) -> float:
        """For a part on its side: 0, or for a gripper that turns parts about its fingers (``turn_about_fingers``)
        the turn about the vertical (nearest zero) that closes them along the horizontal axis the part's
        re-orientation turns it about."""
        gripper = self.sim.robot.arm(arm).gripper
        if gripper is None or not gripper.turn_about_fingers:
            return 0.0
        axis = np.cross(t[:3, 2], [0.0, 0.0, 1.0])
        fingers = self.fingers_axis(self.top_down_rotation(arm), arm)
        if float(np.linalg.norm(axis[:2])) < 1e-6 or float(np.linalg.norm(fingers[:2])) < 1e-6:
            return 0.0
        turn = math.atan2(axis[1], axis[0]) - math.atan2(fingers[1], fingers[0])
        turn = (turn + math.pi / 2.0) % math.pi - math.pi / 2.0  # either way along the axis: the fingers are alike
        return 0.0 if abs(turn) < UNTURNED else turn

    def grasp_height(self, name: str, arm: str, clearance: float, rotation: np.ndarray | None = None) -> float:
        """Where the end-effector frame goes for a grasp of ``name``, above the top of it (negative: below).

        A fixed-constraint grasp stops ``clearance`` above the top; a friction grasp (:meth:`Simulation.fits
        <bt_meta.world.simulation.sim.Simulation.fits>`) centres the finger pads on the highest of the part's
        widest pieces across the fingers (a block's body below its studs, the housing's flange), at most the
        gripper's ``depth`` below the top, with the fingertips on that piece and never within 4 mm of the part's
        bottom. Where that section lies deeper than ``depth`` allows, or the grasp goes over another section
        than the centroid's (:meth:`grasp_xy` with the ``arm`` and ``rotation``), the pads go on the section's
        widest band from the part's cross-sections (:func:`~bt_meta.world.simulation.sections.widest_section`),
        deeper than ``depth``: a round section lying down is widest at its axis, and above it the pads close on a
        slope and the part turns in them (the housing lying on its side, held 2 cm below its flange's top, stood
        up tilted and fell back)."""
        depth = self._band_depth(name, arm)
        if depth is None:
            return clearance
        section = self._section(name, arm, rotation)
        if section is None:
            return -max(0.0, depth)
        top = self.object_top(name)
        gripper = self.sim.robot.arm(arm).gripper
        assert gripper is not None
        pad = (top - depth - gripper.fingertip, top - depth + gripper.fingertip)  # the pads' heights, centred
        if section.moved or (top - depth > section.high + 1e-4 and square_contact(
                self.sim.object_model(name), self.sim.object_transform(name), self._fingers_now(arm, rotation),
                (section.x, section.y), *pad) < SQUARE_CONTACT):
            bottom = self.object_lowest(name)
            depth = min(top - 0.5 * (section.low + section.high), top - section.low - gripper.fingertip - 0.001,
                        top - bottom - gripper.fingertip - 0.004)
        return -max(0.0, depth)

    def _band_depth(self, name: str, arm: str) -> float | None:
        """How far below the top a friction grasp centres its pads by the pieces' height bands (``None``: not a
        friction grasp) -- :meth:`grasp_height` without the cross-sections."""
        sim = self.sim
        if not sim.grasps_by_friction(name, arm):
            return None
        gripper = sim.robot.arm(arm).gripper
        t = sim.object_transform(name)
        axis = sim.closing_axis(arm)
        parts = [part.corners() @ t[:3, :3].T + t[:3, 3] for part in sim.object_model(name).parts]
        spans = [(float(p[:, 2].min()), float(p[:, 2].max())) for p in parts]
        pieces = []  # (width across the fingers, lowest z, highest z) of each height band the parts make
        for low, high in sorted(set(spans)):
            middle = 0.5 * (low + high)
            along = np.concatenate([p for p, (a, b) in zip(parts, spans, strict=True) if a <= middle <= b]) @ axis
            pieces.append((float(along.max() - along.min()), low, high))
        widest = max(width for width, _, _ in pieces)
        _, low, high = max((p for p in pieces if p[0] >= widest - 0.002), key=lambda p: p[2])
        top, bottom = self.object_top(name), self.object_lowest(name)
        # the fingertips stay on the band (below it they would close past a flange onto the narrower body)
        return min(top - 0.5 * (low + high), gripper.depth, top - low - gripper.fingertip - 0.001,
                   top - bottom - gripper.fingertip - 0.004)

    def allow_objects(self, name: str, others: Iterable[str]) -> None:
        """Let object ``name`` touch the ``others`` in collision checks (a part going into a hole)."""
        parts = [p for other in others for p in self._geometry.get(other, [])]
        for part in self._geometry.get(name, []):
            self.collision.allow(part, parts)

    def robot_contacts(self, arm: str) -> list[str]:
        """What the robot touches in the simulator, except the object it holds: ``table`` or object names."""
        import pybullet

        sim = self.sim
        held = {sim.held(a) for a in sim.robot.arms}
        out: set[str] = set()
        for contact in pybullet.getContactPoints(bodyA=sim.robot_id, physicsClientId=sim.client):
            other = contact[2]
            if other == sim.table_id:
                out.add("table")
            else:
                name = sim.object_name_of(other) or sim.obstacle_name_of(other)
                if name is not None and name not in held:
                    out.add(name)
        return sorted(out)

    def object_lowest(self, name: str) -> float:
        """Lowest z of an object's geometry (base frame)."""
        model = self.sim.object_model(name)
        t = self.sim.object_transform(name)
        return float((model.points() @ t[:3, :3].T + t[:3, 3])[:, 2].min())

    def object_top(self, name: str) -> float:
        """Highest z of an object's geometry (base frame)."""
        model = self.sim.object_model(name)
        t = self.sim.object_transform(name)
        points = model.points() @ t[:3, :3].T + t[:3, 3]
        return float(points[:, 2].max())

    def contact_object(self, name: str) -> str:
        """The object a collision geometry name belongs to."""
        return name.split(_PART, 1)[0]

    # -- grounding ----------------------------------------------------------------------------------------------

    def object_name(self, symbol: str) -> str:
        """The simulator object a task-file symbol stands for; :class:`SkillAbort` (``unknown_entity``) if absent."""
        name = self.grounding.objects.get(symbol, symbol)
        if name not in self.sim.object_names():
            raise SkillAbort(FailureKind.UNKNOWN_ENTITY, f"there is no object {name!r} in the world"
                             + (f" (task-file symbol {symbol!r})" if name != symbol else ""),
                             {"object": name, "symbol": symbol, "present": list(self.sim.object_names())})
        return name

    def feature_of(self, symbol: str) -> tuple[str, str | None]:
        """(object, feature name) of a task-file feature symbol, or (object, None) for an object's primary one."""
        spec = self.grounding.features.get(symbol)
        if spec is None:
            return self.object_name(symbol), None
        return self.object_name(str(spec["object"])), spec.get("feature")

    def stack_top(self, name: str) -> float:
        """Highest point of ``name`` and of whatever rests on it around its centroid (e.g. a joined part)."""
        sim = self.sim
        centre = sim.object_transform(name)[:3, 3]
        low, high = sim.object_model(name).extent()
        radius = 0.5 * float(min(high[0] - low[0], high[1] - low[1]))
        top = self.object_top(name)
        for other in sim.object_names():
            if other == name or other in {sim.held(a) for a in sim.robot.arms}:
                continue
            position = sim.object_transform(other)[:3, 3]
            if np.linalg.norm(position[:2] - centre[:2]) < radius and position[2] > centre[2]:
                top = max(top, self.object_top(other))
        return top

    def rebind_object(self, symbol: str, name: str) -> None:
        """Ground the task-file object ``symbol`` as the simulator object ``name`` from now on (a spare standing in
        for a missing part): poses defined over the symbol follow. This world's grounding only; the file is kept."""
        if name not in self.sim.object_names():
            raise BtMetaError(f"cannot rebind {symbol!r}: there is no object {name!r} in the world")
        old = self.grounding.objects.get(symbol, symbol)  # a symbol the grounding does not map names its object
        if old != name:  # a second rebinding keeps the demonstrated name as the key
            original = next((o for o, stand_in in self.stand_ins.items() if stand_in == old), old)
            self.stand_ins[original] = name
        self.grounding = dataclasses.replace(self.grounding, objects={**self.grounding.objects, symbol: name})

    def register_pose(self, symbol: str) -> bool:
        """Make a durable pose symbol (:func:`pose_symbol`) known: its type fact ``pose(symbol)`` joins the symbolic
        state (typed primitives check it). False, and nothing changes, for any other symbol."""
        if parse_pose_symbol(symbol) is None and parse_held_pose_symbol(symbol) is None:
            return False
        if ("pose", symbol) not in self._state:
            self.apply_symbolic([("pose", symbol)], [])
        return True

    def pose_spec(self, symbol: str) -> dict[str, Any]:
        spec = self.grounding.poses.get(symbol)
        if spec is None and (values := parse_pose_symbol(symbol)) is not None:
            return {"pose": [*values[:3], *(math.degrees(v) for v in values[3:])], "frame": "base"}
        if spec is None and (held := parse_held_pose_symbol(symbol)) is not None:
            return {"held_in": held[0], "relative": held[1]}
        if spec is None:
            known = ", ".join(self.grounding.poses) or "none"
            raise SkillAbort(FailureKind.INTERNAL, f"no pose symbol {symbol!r} in {self.grounding.path}; "
                                                   f"known: {known}", {"symbol": symbol})
        return spec

    def top_down_rotation(self, arm: str | None = None) -> np.ndarray:
        """The gripper's rotation (3x3, base frame) pointing straight down with the arm's ``top_down_yaw``: how
        the skills grasp from above, on this robot."""
        yaw = self.sim.robot.arm(arm or self.default_arm).top_down_yaw
        return rpy_to_matrix(math.pi, 0.0, yaw)

    def ground_pose(self, symbol: str, arm: str | None = None) -> np.ndarray:
        """The gripper pose (4x4, base frame) a pose symbol of the task file stands for, now.

        Kinds of entries (``rpy`` in degrees, default pointing down with the arm's ``top_down_yaw``):

        * ``pose: [x, y, z, roll, pitch, yaw]`` -- absolute (an instructor's pose; metres, degrees);
        * ``pose: [x, y, z]`` -- absolute, pointing down with the arm's ``top_down_yaw`` (where the hand's turn
          does not matter: another robot's yaw would turn the wrist half round with the part held);
        * ``above: OBJECT, height: h`` -- top-down over the object's grasp point (its catalogue grasp frame, else
          its centroid), ``h`` above the top of it and of whatever rests on it (grasp poses: a few millimetres;
          ``touch: true`` marks a grasp pose: a friction grasp goes as deep as :meth:`grasp_height` says);
        * ``above_feature: FEATURE, height: h`` -- the held object's lowest point ``h`` above the feature's point,
          its centroid over it (the gripper itself when nothing is held);
        * ``relative_to: OBJECT, offset: [dx, dy, dz]`` -- a point in the object's frame, as it lies now (a pose
          that joins a part to a reference follows the reference: the paper's R_p is a relation between parts,
          not a place on the table); pointing down as usual, or with ``rpy`` given in the object's frame;
        * ``anchor: NAME, offset: [dx, dy, dz]`` -- a scene anchor plus an offset; with ``turn_up: OBJECT``
          (and ``turn``, degrees, default 90) the gripper turned by at most that toward standing the object on
          its base (:meth:`turn_up`): a re-orientation's turn for whichever way the part lies; with ``lowest:
          h``, while it (without ``turn_up``: anything) is held, lowered so its lowest point is ``h`` over the
          anchor (up to the offset's height where the arm does not reach that low).
        """
        arm = arm or self.default_arm
        spec = self.pose_spec(symbol)
        if "held_in" in spec:
            return self.held_pose(str(spec["held_in"]), spec["relative"], arm)
        # default: pointing down, the hand turned as the arm's description says top-down means (Baxter 180, Panda 0)
        down = spec.get("rpy", [180.0, 0.0, math.degrees(self.sim.robot.arm(arm).top_down_yaw)])
        out = np.eye(4)
        out[:3, :3] = rpy_to_matrix(*(math.radians(float(v)) for v in down))
        height = float(spec.get("height", 0.0))
        if "pose" in spec:
            values = [float(v) for v in spec["pose"]]  # 3 or 6 numbers (load_grounding checks)
            x, y, z = values[:3]
            if spec.get("frame") != "base":  # the grounding file's poses are in the scene frame
                dx, dy, dz = self.sim.robot.scene_offset
                x, y, z = x + dx, y + dy, z + dz
            if len(values) == 3:  # the hand's turn is the robot's: no half turn of the wrist for another's yaw
                out[:3, 3] = (x, y, z)
                return out
            roll, pitch, yaw = values[3:]
            return pose_to_matrix((x, y, z, math.radians(roll), math.radians(pitch), math.radians(yaw)))
        if "relative_to" in spec:
            frame = self.sim.object_transform(self.object_name(str(spec["relative_to"])))
            out[:3, 3] = frame[:3, :3] @ np.asarray([float(v) for v in spec.get("offset", (0.0, 0.0, 0.0))]) \
                + frame[:3, 3]
            if "rpy" in spec:
                out[:3, :3] = frame[:3, :3] @ out[:3, :3]
            return out
        if "above" in spec:
            name = self.object_name(str(spec["above"]))
            if "rpy" not in spec:  # grasped relative to itself: as it would be, turned back by its own heading
                out[:3, :3] = rpy_to_matrix(0.0, 0.0, self.own_heading(name, arm)) @ out[:3, :3]
            if spec.get("touch"):  # a grasp pose: as deep as this gripper grasps
                height = self.grasp_height(name, arm, height, out[:3, :3])
            x, y = self.grasp_xy(name, arm, out[:3, :3])
            out[:3, 3] = (x, y, self.stack_top(name) + height)
            return out
        if "above_feature" in spec:
            obj, feature = self.feature_of(str(spec["above_feature"]))
            point, _ = self.sim.feature(obj, feature)
            held = self.sim.held(arm)
            if held is None:
                out[:3, 3] = np.asarray(point) + np.array([0.0, 0.0, height])
                return out
            gripper = self.sim.link_transform(self.end_effector(arm)).copy()
            t = self.sim.object_transform(held)
            points = self.sim.object_model(held).points() @ t[:3, :3].T + t[:3, 3]
            lowest = float(points[:, 2].min())
            gripper[:3, 3] += (point[0] - t[0, 3], point[1] - t[1, 3], point[2] + height - lowest)
            return gripper
        if "anchor" in spec:
            position, _ = self.anchor(str(spec["anchor"]))
            offset = [float(v) for v in spec.get("offset", (0.0, 0.0, 0.0))]
            if "turn_up" in spec:
                part, key = self.object_name(str(spec["turn_up"])), (str(spec["anchor"]), str(spec["turn_up"]))
                if self.sim.held(arm) != part and key in self._turned_at:
                    out[:3, :3] = self._turned_at[key]  # let go here after the turn: leave as it was held
                else:
                    flip = [float(v) for v in spec.get("flip_axis", (1.0, 0.0, 0.0))]
                    gripper = self.sim.robot.arm(arm).gripper
                    if gripper is not None and gripper.turn_about_fingers:  # flipped about the fingers, level
                        flip = list(self.fingers_axis(out[:3, :3], arm))
                    out[:3, :3] = self.turn_up(str(spec["turn_up"]), math.radians(float(spec.get("turn", 90.0))),
                                               out[:3, :3], arm, np.asarray(flip)) @ out[:3, :3]
                    if self.sim.held(arm) == part:
                        out[:3, :3] = self._reachable_yaw(out[:3, :3], np.asarray(position) + np.asarray(offset),
                                                          arm, self._turned_at.get(key))
                        self._turned_at[key] = out[:3, :3].copy()
            position = self._clear_of_others(str(spec["anchor"]), position, spec, arm, out[:3, :3], offset)
            out[:3, 3] = np.asarray(position) + np.asarray(offset)
            if "turn_up" in spec:
                if "lowest" in spec and self.sim.held(arm) == self.object_name(str(spec["turn_up"])):
                    self._lowest_over(out, position, float(spec["lowest"]), float(offset[2]), arm)
            elif "lowest" in spec and self.sim.held(arm) is not None:  # not turned: by whatever is held, as it lies
                self._lowest_over(out, position, float(spec["lowest"]), float(offset[2]), arm)
            return out
        raise SkillAbort(FailureKind.INTERNAL,
                         f"pose {symbol!r} in {self.grounding.path}: give pose, above, above_feature, relative_to "
                         "or anchor")

    def _clear_of_others(self, anchor: str, position: tuple[float, float, float], spec: Mapping[str, Any], arm: str,
                         rotation: np.ndarray, offset: Sequence[float]) -> tuple[float, float, float]:
        """Where a part is put down at ``anchor``: the anchor, or the nearest spot around it clear of every other
        object and obstacle (:func:`~bt_meta.world.simulation.free_spots.nearest_free_spot`) when something lies
        there, where the gripper reaches at ``offset`` over it turned by ``rotation``. The part is the one held
        (else the one ``turn_up`` names); its footprint is every point it can reach turning about the gripper.
        The spot chosen is kept while it stays clear (the lower pose and the retreat after letting go come to the
        same place): the part last put down at the anchor is remembered and not counted as in the way."""
        import pinocchio as pin

        from bt_meta.world.simulation.free_spots import nearest_free_spot

        sim = self.sim
        held = sim.held(arm)
        before = self._put_down_at.get(anchor)
        if held is not None:
            tcp = sim.link_transform(self.end_effector(arm))[:3, 3]
            t = sim.object_transform(held)
            points = sim.object_model(held).points() @ t[:3, :3].T + t[:3, 3]
            radius = float(np.max(np.linalg.norm(points - tcp, axis=1)))
            if before is not None and before[0] == held:
                radius = max(radius, before[1])  # the same part, held another way since: the larger footprint
            self._put_down_at[anchor] = (held, radius, before[2] if before and before[0] == held else None)
        elif "turn_up" in spec and (before is None or before[0] != self.object_name(str(spec["turn_up"]))):
            return position  # the part is not in the hand yet and was never put down here: nothing to clear
        if anchor not in self._put_down_at:
            return position
        part, radius, chosen = self._put_down_at[anchor]

        def reached(x: float, y: float) -> bool:
            target = pin.SE3(rotation, np.array([x, y, position[2]]) + np.asarray(offset, dtype=float))
            return bool(self.ik.solve(arm, target, self.current_q(), seed=self.seed).success)

        footprints = []
        for name in sim.object_names():
            if name != part and name not in {sim.held(a) for a in sim.robot.arms}:
                t = sim.object_transform(name)
                footprints.append((sim.object_model(name).points() @ t[:3, :3].T + t[:3, 3])[:, :2])
        for model, t in sim.obstacles().values():
            footprints.append((model.points() @ t[:3, :3].T + t[:3, 3])[:, :2])
        spot = nearest_free_spot(position[:2], radius, footprints, sim.table.bounds, prefer=chosen, accept=reached)
        self._put_down_at[anchor] = (part, radius, spot)
        return position if spot is None else (spot[0], spot[1], position[2])

    def _reachable_yaw(self, rotation: np.ndarray, position: np.ndarray, arm: str,
                       before: np.ndarray | None) -> np.ndarray:
        """``rotation`` turned about the vertical by 0, 90, -90 or 180 degrees: the turn chosen last time
        (``before``) while the arm still reaches ``position`` so (collision-aware IK), else the one whose solution
        is nearest the arm's joints now. The part held turns about the vertical with it and lands on the same face,
        while which wrist pose a robot reaches well depends on its arm (the UR5 by the set-down spot)."""
        import pinocchio as pin

        vertical = np.array([0.0, 0.0, 1.0])
        q_now = self.current_q()
        indices = self.kin.arm_indices(arm)
        best: tuple[float, np.ndarray] | None = None
        for angle in (0.0, 90.0, -90.0, 180.0):
            candidate = axis_angle_matrix(vertical, math.radians(angle)) @ rotation
            solved = self.ik.solve(arm, pin.SE3(candidate, np.asarray(position, float)), q_now, seed=self.seed)
            if not solved.success or solved.q is None:
                continue
            if before is not None and float(np.linalg.norm(pin.log3(before.T @ candidate))) < 1e-3:
                return candidate
            distance = float(np.max(np.abs(solved.q[indices] - q_now[indices])))
            if best is None or distance < best[0]:
                best = (distance, candidate)
        return rotation if best is None else best[1]

    def held_pose(self, relative_to: str, pose: Sequence[float], arm: str | None = None) -> np.ndarray:
        """The gripper pose that puts the object held now at ``pose`` (x, y, z, roll, pitch, yaw; metres, radians)
        in the frame of ``relative_to`` (a task-file symbol or an object name), through the current grasp; with
        nothing held, the gripper itself goes there."""
        arm = arm or self.default_arm
        target = self.sim.object_transform(self.object_name(relative_to)) @ pose_to_matrix([float(v) for v in pose])
        held = self.sim.held(arm)
        if held is None:
            return target
        return target @ np.linalg.inv(self.held_relative(arm))
    def _lowest_over(self, pose: np.ndarray, point: Sequence[float], lowest: float, most: float, arm: str) -> None:
        """Lower ``pose`` (turned, holding a part) so the held part's lowest point is ``lowest`` over ``point``
        (a part let go low lands as turned, a top-heavy one does not topple) -- raised back, 1 cm at a time up to
        ``most`` over it, where the turned wrist does not reach that low."""
        import pinocchio as pin

        t = pose @ self.held_relative(arm)
        points = self.sim.object_model(self.sim.held(arm)).points() @ t[:3, :3].T + t[:3, 3]
        pose[2, 3] += float(point[2]) + lowest - float(points[:, 2].min())
        while pose[2, 3] < float(point[2]) + most:
            solved = self.ik.solve(arm, pin.SE3(pose[:3, :3], pose[:3, 3]), self.current_q(), seed=self.seed)
            if solved.success:
                return
            pose[2, 3] = min(pose[2, 3] + 0.01, float(point[2]) + most)

    def turn_up(self, symbol: str, most: float, grip: np.ndarray, arm: str, flip: np.ndarray) -> np.ndarray:
        """The rotation (3x3, base frame) of a gripper held at orientation ``grip`` that turns object ``symbol``
        by at most ``most`` toward standing on its base (its z axis up), about the horizontal axis that does it
        soonest; upside down (more than 135 degrees off, where that axis is noise) about ``flip``; then about the
        vertical so the gripper points as a turn about ``flip`` would point it. Measured from how the gripper
        holds it (or, not held, how a grasp at ``grip`` would), so the pose stays the same while the turn is under
        way."""
        name = self.object_name(symbol)
        if self.sim.held(arm) == name:
            up = grip @ self.held_relative(arm)[:3, 2]
        else:
            up = self.sim.object_transform(name)[:3, 2]
            if self.sim.robot.arm(arm).gripper is not None and self.sim.robot.arm(arm).gripper.turn_about_fingers:
                up = rpy_to_matrix(0.0, 0.0, -self.own_heading(name, arm)) @ up  # grasped turned by its heading
        vertical = np.array([0.0, 0.0, 1.0])
        angle = math.acos(max(-1.0, min(1.0, float(up @ vertical))))
        axis = np.cross(up, vertical)
        if angle > math.radians(135.0) or float(np.linalg.norm(axis)) < 1e-6:
            axis = flip - (flip @ vertical) * vertical
        turn = axis_angle_matrix(axis, min(angle, most))
        # Then about the vertical (the part stays as turned) so the gripper points where the turn about ``flip``
        # points it: one wrist pose however the part lies, the one a fixed turn (the grounding's) reaches.
        flat = flip - (flip @ vertical) * vertical
        wanted = (axis_angle_matrix(flat, math.pi / 2.0) @ grip)[:2, 2]
        pointing = (turn @ grip)[:2, 2]
        if float(np.linalg.norm(wanted)) < 1e-6 or float(np.linalg.norm(pointing)) < 1e-6:
            return turn
        yaw = math.atan2(wanted[1], wanted[0]) - math.atan2(pointing[1], pointing[0])
        return axis_angle_matrix(vertical, yaw) @ turn

    def anchor(self, name: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """A scene anchor's position (z on the table top when the file says ``table``) and rpy."""
        anchors = getattr(self.scene, "anchors", {}) or {}
        if name not in anchors:
            raise SkillAbort(FailureKind.INTERNAL, f"scene {self.scene.name!r} has no anchor {name!r}; "
                                                   f"anchors: {', '.join(anchors) or 'none'}")
        (x, y, z), rpy = anchors[name]
        dx, dy, dz = self.sim.robot.scene_offset
        return (x + dx, y + dy, self.sim.table.top_z if z is None else z + dz), tuple(rpy)

    def ground_cell(self, frame: str, x: str, y: str) -> tuple[float, float, float]:
        """A point (x, y) of a task-file frame (e.g. letter cells in lb) -> (X, Y, yaw) on the table."""
        spec = self.grounding.frames.get(frame)
        if spec is None:
            raise SkillAbort(FailureKind.INTERNAL, f"no frame {frame!r} in {self.grounding.path}")
        try:
            u, v = float(x), float(y)
        except ValueError:
            raise SkillAbort(FailureKind.INTERNAL, f"frame {frame!r}: coordinates must be numbers, got {x}, {y}",
                             {"x": x, "y": y}) from None
        (ox, oy, _), (_, _, yaw) = self.anchor(str(spec["anchor"]))
        unit = float(spec.get("unit", 1.0))
        c, s = math.cos(yaw), math.sin(yaw)
        return ox + unit * (c * u - s * v), oy + unit * (s * u + c * v), yaw

    def frame_support(self, frame: str) -> tuple[float, str | None]:
        """(z, support) of a task-file frame: the height (base frame) its anchor gives -- the table top for an
        anchor ``z: table`` -- and the object or obstacle the frame's ``support:`` names (a tray, a fixture, a part
        to stack on), or ``None``. What a place into the frame rests the part on (:meth:`surface_under`)."""
        spec = self.grounding.frames.get(frame)
        if spec is None:
            raise SkillAbort(FailureKind.INTERNAL, f"no frame {frame!r} in {self.grounding.path}")
        (_, _, z), _ = self.anchor(str(spec["anchor"]))
        support = spec.get("support")
        return z, None if support is None else str(support)

    def surface_under(self, support: str, points: np.ndarray) -> float | None:
        """The highest top (base frame z) of the pieces of ``support`` (an object or a static obstacle) that lie
        under any of ``points`` (x, y rows), or ``None`` when none does: a tray's floor under a slot, not its rim
        beside it; the top of the part a part is stacked on."""
        if support in self.sim.object_names():
            model, transform = self.sim.object_model(support), self.sim.object_transform(support)
        elif support in self.sim.obstacles():
            model, transform = self.sim.obstacles()[support]
        else:
            return None
        top: float | None = None
        for part in model.parts:
            turn = rpy_to_matrix(*part.rpy)
            own = (part.corners() - np.asarray(part.position, dtype=float)) @ turn  # in the part's frame
            low, high = own.min(axis=0), own.max(axis=0)
            rotation = transform[:3, :3] @ turn
            centre = transform[:3, :3] @ np.asarray(part.position, dtype=float) + transform[:3, 3]
            local = (np.column_stack([points[:, 0], points[:, 1], np.full(len(points), centre[2])]) - centre) \
                @ rotation
            over = np.all((local[:, :2] >= low[:2] - 1e-4) & (local[:, :2] <= high[:2] + 1e-4), axis=1)
            if over.any():
                height = float((part.corners() @ transform[:3, :3].T + transform[:3, 3])[:, 2].max())
                top = height if top is None else max(top, height)
        return top

    def put_down_problem(self, name: str, frame: str, x: float, y: float, clearance: float = 0.01) -> str | None:
        """Why object ``name`` could not be put down at point (x, y) of ``frame`` as the place skill lays it (its
        axes along the frame's, on the table), or ``None`` when it could: another object or a static obstacle
        closer than ``clearance`` to where it would lie, or no IK solution for the top-down gripper over it or
        down at it. What a repair asks before it sets a block aside."""
        import pinocchio as pin

        sim = self.sim
        gx, gy, yaw = self.ground_cell(frame, str(x), str(y))
        low, high = sim.object_model(name).extent()
        size = np.asarray(high, dtype=float) - np.asarray(low, dtype=float)
        pose = pose_to_matrix((gx, gy, sim.table.top_z + size[2] / 2.0 + 0.002, 0.0, 0.0, yaw))
        others = [n for n in sim.object_names() if n != name and n not in {sim.held(a) for a in sim.robot.arms}]
        near = sim.box_clearances(size, pose, [*others, *sim.obstacles()], clearance)
        if near:
            closest = min(near, key=lambda n: near[n])
            return f"{closest} within {clearance * 100:.0f} cm of ({x:g}, {y:g})"
        arm = self.default_arm
        rotation = rpy_to_matrix(math.pi, 0.0, sim.robot.arm(arm).top_down_yaw)
        for height in (size[2] + 0.08, size[2] - 0.004):
            target = pin.SE3(rotation, np.array([gx, gy, sim.table.top_z + height]))
            if not self.ik.solve(arm, target, self.current_q(), seed=self.seed).success:
                return f"no IK solution for the gripper over ({x:g}, {y:g})"
        return None

    # -- internals ----------------------------------------------------------------------------------------------

    def _check_objects(self, problem_name: str) -> None:
        """The problem's symbols must mean something here: objects of type ``pose`` need a pose grounding, of
        type ``feature`` a feature grounding (or name an object), every other object must be in the nominal scene
        (a variant may replace objects: that is its point)."""
        objects = getattr(self.problem, "objects", None) or {}
        groups = objects.items() if isinstance(objects, Mapping) else [("object", objects)]
        poses = [o for kind, group in groups if kind == "pose" for o in group]
        where = self.grounding.path
        unposed = [p for p in poses if p not in self.grounding.poses]
        if unposed:
            raise ConfigError(f"problem {problem_name!r}: pose symbols without a grounding under `poses:`: "
                              f"{', '.join(unposed)}", where)
        if self.variant != "nominal":
            return
        names = [o for kind, group in groups if kind != "pose" for o in group if o not in self.grounding.features]
        present = set(self.sim.object_names())
        missing = sorted(n for n in names if self.grounding.objects.get(n, n) not in present)
        if missing:
            raise ConfigError(f"problem {problem_name!r} names objects the scene {self.scene.name!r} lacks: "
                              f"{', '.join(missing)}", self.scene.path)

    def _check_supports(self) -> None:
        """Every frame's ``support:`` names an object or obstacle of the scene lying under the frame's anchor,
        else a located error (the grounding file's line) before anything moves."""
        for frame, spec in self.grounding.frames.items():
            support = spec.get("support")
            if support is None:
                continue
            line, column = _position_in(self.grounding.path, ("frames", frame, "support"))
            if str(support) not in self.sim.object_names() and str(support) not in self.sim.obstacles():
                known = ", ".join([*self.sim.object_names(), *self.sim.obstacles()]) or "none"
                raise ConfigError(f"frames.{frame}.support: the scene {self.scene.name!r} has no object or obstacle "
                                  f"{support!r}; it has {known}", self.grounding.path, line, column)
            anchor = str(spec.get("anchor"))
            try:
                (x, y, _), _ = self.anchor(anchor)
            except SkillAbort as error:
                raise ConfigError(f"frames.{frame}.anchor: {error.message}", self.grounding.path) from None
            if self.surface_under(str(support), np.array([[x, y]])) is None:
                t = (self.sim.object_transform(str(support)) if str(support) in self.sim.object_names()
                     else self.sim.obstacles()[str(support)][1])
                raise ConfigError(f"frames.{frame}.support: {support!r} (at x {t[0, 3]:.3f}, y {t[1, 3]:.3f}) is not "
                                  f"under the frame's anchor {anchor!r} (at x {x:.3f}, y {y:.3f}, base frame)",
                                  self.grounding.path, line, column)

    def _arm_hand_links(self, arm: str) -> list[str]:
        """Robot links moved by the arm's last joint (hand, gripper, fingers): a held object may touch them.

        Called before any scene object is added, so every geometry is the robot's."""
        model = self.kin.model
        last = model.getJointId(self.sim.robot.arm(arm).joints[-1])
        links = {model.frames[obj.parentFrame].name for obj in self.collision.geometry.geometryObjects
                 if last in model.supports[obj.parentJoint]}
        return sorted(links)

    def _add_shape(self, name: str, kind: str, dims: tuple[float, ...], pose: np.ndarray) -> None:
        if kind == "box":
            self.collision.add_box(name, dims, pose)
        elif kind == "cylinder":
            self.collision.add_cylinder(name, dims[0], dims[1], pose)
        else:
            self.collision.add_convex(name, np.asarray(dims, dtype=float).reshape(-1, 3), pose)

    def sync_collision(self) -> None:
        """Mirror the simulator's objects into the collision scene (held objects ride with the gripper)."""
        sim, checker = self.sim, self.collision
        names = set(sim.object_names())
        for name in [n for n in self._geometry if n not in names]:
            for part in self._geometry.pop(name):
                checker.remove(part)
        held = {sim.held(arm) for arm in sim.robot.arms}
        for name in sorted(names):
            transform = sim.object_transform(name)
            shapes = _collision_shapes(sim.object_model(name))
            if name not in self._geometry:
                parts = []
                for k, (kind, dims, local) in enumerate(shapes):
                    part = name if k == 0 else f"{name}{_PART}{k}"
                    self._add_shape(part, kind, dims, transform @ local)
                    parts.append(part)
                self._geometry[name] = parts
            elif name not in held:
                for part, (_, _, local) in zip(self._geometry[name], shapes, strict=True):
                    checker.move(part, transform @ local)
        q = None
        for arm in sim.robot.arms:  # a part held by friction may have turned in the fingers: carry it as it is now
            name = sim.held(arm)
            if name is None or not sim.holds_by_friction(arm) or name not in self._geometry:
                continue
            q = self.current_q() if q is None else q
            transform = sim.object_transform(name)
            shapes = _collision_shapes(sim.object_model(name))
            for part, (_, _, local) in zip(self._geometry[name], shapes, strict=True):
                checker.detach(part, pose=transform @ local)
                checker.attach(part, self.end_effector(arm), q, allow=self._hand_links[arm])
        for a, b in sim.attachments():  # magnetically joined parts touch by construction: not a collision
            for part in self._geometry.get(a, []):
                checker.allow(part, self._geometry.get(b, []))




def _position_in(path: Path, keys: Sequence[str]) -> tuple[int | None, int | None]:
    """(line, column), 1-based, of the value at ``keys`` in a YAML file; ``None``s when it is not found."""
    import yaml

    from bt_meta.safe_yaml import compose_yaml

    try:
        node = compose_yaml(path.read_text(encoding="utf-8"), str(path), ConfigError)
    except (OSError, ConfigError):
        return None, None
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            return None, None
        node = next((v for k, v in node.value if getattr(k, "value", None) == key), None)
        if node is None:
            return None, None
    return node.start_mark.line + 1, node.start_mark.column + 1


def _collision_shapes(model: ObjectModel) -> list[tuple[str, tuple[float, ...], np.ndarray]]:
    """Boxes and cylinders for the collision checker: the model's parts, or their convex hull when it has many (a
    hollow tube of 24 boxes checks as its hull: the gripper never goes inside it). The hull, not the bounding box:
    a round part lying on its side at any roll keeps its box's corners under the table, and every path lifting it
    from there collided (the housings' re-grasp, generated housing variants 0005 0036 0041)."""

    def shrunk(*sizes: float) -> tuple[float, ...]:
        return tuple(max(1e-3, s - 2.0 * SHRINK) for s in sizes)

    if len(model.parts) > 6:
        points = np.concatenate([_shrunk_part(part).corners() for part in model.parts])
        return [("convex", tuple(float(v) for v in points.ravel()), np.eye(4))]
    out: list[tuple[str, tuple[float, ...], np.ndarray]] = []
    for part in model.parts:
        local = pose_to_matrix((*part.position, *part.rpy))
        if isinstance(part, Box):
            out.append(("box", shrunk(*part.size), local))
        elif isinstance(part, Cylinder):
            radius, length = shrunk(2.0 * part.radius, part.length)
            out.append(("cylinder", (radius / 2.0, length), local))
        elif isinstance(part, Mesh):  # its convex hull, as pybullet collides a moving mesh
            out.append(("convex", tuple(float(v) for row in part.vertices for v in row), local))
    return out



def _shrunk_part(part: Box | Cylinder | Mesh) -> Box | Cylinder | Mesh:
    """``part`` made :data:`SHRINK` smaller on every side (a mesh: its vertices drawn that far toward its centre)."""
    if isinstance(part, Box):
        return dataclasses.replace(part, size=tuple(max(1e-3, s - 2.0 * SHRINK) for s in part.size))
    if isinstance(part, Cylinder):
        return dataclasses.replace(part, radius=max(5e-4, part.radius - SHRINK),
                                   length=max(1e-3, part.length - 2.0 * SHRINK))
    vertices = np.asarray(part.vertices, dtype=float)
    centre = vertices.mean(axis=0)
    offset = vertices - centre
    length = np.maximum(np.linalg.norm(offset, axis=1, keepdims=True), 1e-9)
    inset = centre + offset * np.maximum(0.0, 1.0 - SHRINK / length)
    return dataclasses.replace(part, vertices=tuple(tuple(float(v) for v in row) for row in inset))

@hookimpl
def bt_meta_make_world(name: str, domain: Any, problem: Any, options: dict[str, Any]) -> SimWorld | None:
    if name != "sim":
        return None
    grounding = load_grounding(domain.name, options.get("task_file"), options.get("grounding"))
    return SimWorld(domain, problem, grounding, variant=options.get("variant"), seed=int(options.get("seed", 0)),
                    gui=bool(options.get("gui", False)), robot=options.get("robot"), scene=options.get("scene"))

