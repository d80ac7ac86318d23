"""Robot descriptions as data: load ``robots/NAME.yaml`` and check it against the robot's URDF.

Offers:

* :func:`load_robot` -- a :class:`RobotDescription` from a shipped name (``"baxter"``) or a YAML path
* :class:`RobotDescription` -- model files, arms, cameras, home pose, joint limits (``joint_limit_margin`` keeps IK
  off the URDF limits), IK settings, the workcell offset
* :class:`ArmDescription`, :class:`GripperDescription` (how the simulator grasps: ``fixed`` or ``friction``),
  :class:`IKSettings` -- its parts
* :class:`UrdfSummary` / :func:`read_urdf_summary` -- joint and link names, types and limits of a URDF

A wrong robot file raises :class:`~bt_meta.errors.ConfigError` located at the offending YAML node
(``path:line:column``): a missing key, a wrong type, or a joint or frame that the URDF does not have.
"""

from __future__ import annotations

import importlib.metadata
import math
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import ConfigError, KinematicsError
from bt_meta.model_cache import cached, clear_entry, file_signature
from bt_meta.resources import robots_dir
from bt_meta.world._yaml_nodes import YamlNodeReader, shipped_yaml_path

__all__ = [
    "ArmDescription",
    "GripperDescription",
    "IKSettings",
    "RobotDescription",
    "UrdfSummary",
    "available_robots",
    "load_robot",
    "read_urdf_summary",
]


@dataclass(frozen=True)
class GripperDescription:
    joints: tuple[str, ...]
    open: tuple[float, ...]
    closed: tuple[float, ...]
    opening: float
    """Distance between the open fingers (m)."""
    grasp: str = "fixed"
    """How the simulator holds a part: ``fixed`` (a rigid constraint at the relative pose when the gripper closes:
    the Baxter's gripper is narrower than a Mega Blok) or ``friction`` (the fingers close on the part and hold it
    by contact and friction alone, so heavy or slippery parts slip; a part wider than ``opening`` across the
    fingers is still held by constraint)."""
    force: float = 20.0
    """Friction grasps: the force (N) each finger's motor closes with."""
    depth: float = 0.012
    """Friction grasps: how far below a part's top the end-effector frame goes, so the finger pads overlap it."""
    fingertip: float = 0.0
    """How far the fingertips reach below the end-effector frame (m): a friction grasp keeps them above the
    surface the part stands on."""


@dataclass(frozen=True)
class ArmDescription:
    name: str
    joints: tuple[str, ...]
    end_effector: str
    camera: str | None
    gripper: GripperDescription | None
    top_down_yaw: float = math.pi
    """Yaw (rad, base frame) of the end effector pointing straight down that the arm reaches most comfortably:
    skills grasping top-down pick, of an object's symmetric grasps, the one nearest to it."""


@dataclass(frozen=True)
class IKSettings:
    position_tolerance: float = 1e-4
    orientation_tolerance: float = 1e-3
    lm_damping: float = 1e-2
    orientation_cost: float = 1.0
    max_iterations: int = 15
    max_attempts: int = 40
    stall_iterations: int = 5
    stall_ratio: float = 0.5
    max_colliding_solutions: int = 20
    restart_samples: int = 16
    escape_after: int = 2
    escape_tries: int = 10
    escape_steps: int = 12
    escape_step_size: float = 0.15
    escape_converge_steps: int = 4
    seed: int = 0


@dataclass(frozen=True)
class UrdfSummary:
    """What the loader needs from a URDF: names, joint types, limits and mimic relations."""

    robot_name: str
    links: tuple[str, ...]
    joints: dict[str, str]
    """joint name -> URDF type, in file order."""
    limits: dict[str, tuple[float, float]]
    """movable joint -> (lower, upper); continuous joints get (-inf, inf)."""
    mimic: dict[str, tuple[str, float, float]]
    """mimicking joint -> (mimicked joint, multiplier, offset)."""

    @property
    def movable_joints(self) -> tuple[str, ...]:
        return tuple(name for name, kind in self.joints.items() if kind not in ("fixed", "floating", "planar"))

    @property
    def frames(self) -> frozenset[str]:
        return frozenset(self.links) | frozenset(self.joints)


@dataclass(frozen=True)
class RobotDescription:
    name: str
    source: Path
    """The YAML file this description came from."""
    urdf_path: Path
    srdf_path: Path | None
    package_dirs: tuple[Path, ...]
    srdf_joint_prefix: str
    base_frame: str
    arms: dict[str, ArmDescription]
    head_joints: tuple[str, ...]
    head_camera: str | None
    home: dict[str, float]
    """Every movable joint of the URDF -> its home value (0 unless the file says otherwise)."""
    joint_limits: dict[str, tuple[float, float]]
    ik: IKSettings
    urdf: UrdfSummary = field(repr=False)
    scene_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Where the shared scene frame (scene files, grounding poses: the Baxter's torso frame) lies in this robot's
    base frame: scene coordinates + this = base-frame coordinates. Placement as data, so one scene serves robots
    of different sizes and mounting heights."""

    @property
    def default_arm(self) -> str:
        """The arm skills use when a grounding file names none: the first one the description lists."""
        return next(iter(self.arms))

    def arm(self, name: str) -> ArmDescription:
        arm = self.arms.get(name)
        if arm is None:
            raise KinematicsError(f"robot {self.name!r} has no arm {name!r}; arms: {', '.join(self.arms)}")
        return arm

    @property
    def cameras(self) -> dict[str, str]:
        """Camera name -> frame: ``head`` and ``<arm>_hand``."""
        out = {f"{arm.name}_hand": arm.camera for arm in self.arms.values() if arm.camera}
        if self.head_camera:
            out["head"] = self.head_camera
        return out


def available_robots() -> list[str]:
    return sorted(p.stem for p in robots_dir().glob("*.yaml"))


def load_robot(name: str | Path = "baxter") -> RobotDescription:
    """Load a robot description by shipped name or by path to a YAML file."""
    path = shipped_yaml_path(name, robots_dir(), lambda shipped: f"no robot description {name!r}; available: {shipped}",
                             "robot description file not found")
    return _cached_description(path)


def _cached_description(path: Path) -> RobotDescription:
    """One parse per process while the YAML, URDF and SRDF stay as they are (a campaign worker loads the robot
    once, not once per episode); the description is frozen and nothing mutates its tables."""
    key = ("robot", file_signature(path))
    description, files = cached(key, lambda: _parsed_with_files(path))
    if files != _model_files(description):  # the URDF or SRDF changed under an unchanged YAML
        clear_entry(key)
        description, _ = cached(key, lambda: _parsed_with_files(path))
    return description


def _parsed_with_files(path: Path) -> tuple[RobotDescription, tuple[Any, ...]]:
    description = _RobotFile(path).load()
    return description, _model_files(description)


def _model_files(description: RobotDescription) -> tuple[Any, ...]:
    return (file_signature(description.urdf_path), file_signature(description.srdf_path))


# --------------------------------------------------------------------------------------------------------------
# URDF


def read_urdf_summary(path: Path) -> UrdfSummary:
    text = path.read_text(encoding="utf-8")
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise ConfigError("URDF files with a DOCTYPE or entities are not accepted", path)
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as error:
        line, column = error.position
        raise ConfigError(f"URDF is not well-formed XML: {error}", path, line, column + 1) from None
    if root.tag != "robot":
        raise ConfigError(f"URDF root element is <{root.tag}>, expected <robot>", path, 1)
    links = tuple(el.get("name", "") for el in root.findall("link"))
    joints: dict[str, str] = {}
    limits: dict[str, tuple[float, float]] = {}
    mimic: dict[str, tuple[str, float, float]] = {}
    for el in root.findall("joint"):
        jname, kind = el.get("name", ""), el.get("type", "")
        joints[jname] = kind
        if kind == "continuous":
            limits[jname] = (-math.inf, math.inf)
        elif kind in ("revolute", "prismatic"):
            limit = el.find("limit")
            lower = float(limit.get("lower", "0")) if limit is not None else 0.0
            upper = float(limit.get("upper", "0")) if limit is not None else 0.0
            limits[jname] = (lower, upper)
        m = el.find("mimic")
        if m is not None:
            mimic[jname] = (m.get("joint", ""), float(m.get("multiplier", "1")), float(m.get("offset", "0")))
    return UrdfSummary(root.get("name", ""), links, joints, limits, mimic)


# --------------------------------------------------------------------------------------------------------------
# YAML with positions


class _RobotFile(YamlNodeReader):
    """Walks the composed YAML node tree so that every error can name its line and column."""

    # -- node helpers ------------------------------------------------------------------------------------------

    def integer(self, node: yaml.Node, what: str) -> int:
        value = self.scalar(node, what)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise self.error(f"{what} must be a non-negative integer", node)
        return value

    # -- checks against the URDF -------------------------------------------------------------------------------

    def joint(self, node: yaml.Node, what: str, urdf: UrdfSummary) -> str:
        name = self.string(node, what)
        if name not in urdf.joints:
            raise self.error(f"{what}: unknown joint {name!r} (not in the URDF)", node)
        if name not in urdf.limits:
            raise self.error(f"{what}: joint {name!r} is {urdf.joints[name]}, not movable", node)
        return name

    def frame(self, node: yaml.Node, what: str, urdf: UrdfSummary) -> str:
        name = self.string(node, what)
        if name not in urdf.frames:
            raise self.error(f"{what}: unknown frame {name!r} (no such link or joint in the URDF)", node)
        return name

    # -- the file ----------------------------------------------------------------------------------------------

    def load(self) -> RobotDescription:
        from bt_meta.safe_yaml import compose_yaml
        from bt_meta.user_files import read_user_text

        text = read_user_text(self.path, what="robot description", error=ConfigError)
        root = compose_yaml(text, str(self.path), ConfigError, syntax="not valid YAML")
        if root is None:
            raise ConfigError("the robot description is empty", self.path, 1, 1)
        top = self.mapping(root, "robot description")
        self.check_keys(
            top,
            {"name", "files", "base_frame", "arms", "head", "home", "joint_limits", "joint_limit_margin", "ik",
             "workcell"},
            "robot description",
        )
        name = self.string(self.require(top, "name", root, "robot description"), "name")

        files_node = self.require(top, "files", root, "robot description")
        urdf_path, srdf_path, package_dirs, prefix = self.files(files_node)
        urdf = read_urdf_summary(urdf_path)

        base_frame = self.frame(self.require(top, "base_frame", root, "robot description"), "base_frame", urdf)

        arms_node = self.require(top, "arms", root, "robot description")
        arms = {}
        for arm_name, (_, arm_node) in self.mapping(arms_node, "arms").items():
            arms[arm_name] = self.arm(arm_name, arm_node, urdf)
        if not arms:
            raise self.error("arms: at least one arm is required", arms_node)

        head_joints: tuple[str, ...] = ()
        head_camera = None
        if "head" in top:
            head_node = top["head"][1]
            head = self.mapping(head_node, "head")
            self.check_keys(head, {"joints", "camera"}, "head")
            if "joints" in head:
                head_joints = tuple(
                    self.joint(n, "head.joints", urdf) for n in self.sequence(head["joints"][1], "head.joints")
                )
            if "camera" in head:
                head_camera = self.frame(head["camera"][1], "head.camera", urdf)

        limits = dict(urdf.limits)
        if "joint_limits" in top:
            for jname, (key_node, value_node) in self.mapping(top["joint_limits"][1], "joint_limits").items():
                self.joint(key_node, "joint_limits", urdf)
                pair = self.sequence(value_node, f"joint_limits.{jname}")
                if len(pair) != 2:
                    raise self.error(f"joint_limits.{jname} must be [lower, upper]", value_node)
                lower = self.number(pair[0], f"joint_limits.{jname} lower")
                upper = self.number(pair[1], f"joint_limits.{jname} upper")
                urdf_lower, urdf_upper = urdf.limits[jname]
                if not (urdf_lower <= lower < upper <= urdf_upper):
                    raise self.error(
                        f"joint_limits.{jname}: [{lower}, {upper}] must be increasing and within the URDF limits "
                        f"[{urdf_lower}, {urdf_upper}]",
                        value_node,
                    )
                limits[jname] = (lower, upper)

        if "joint_limit_margin" in top:
            named = set(self.mapping(top["joint_limits"][1], "joint_limits")) if "joint_limits" in top else set()
            self.limit_margin(top["joint_limit_margin"][1], limits, arms, named)

        home = {j: min(max(0.0, limits[j][0]), limits[j][1]) for j in urdf.movable_joints}
        if "home" in top:
            for jname, (key_node, value_node) in self.mapping(top["home"][1], "home").items():
                self.joint(key_node, "home", urdf)
                value = self.number(value_node, f"home.{jname}")
                lower, upper = limits[jname]
                if not lower - 1e-12 <= value <= upper + 1e-12:
                    raise self.error(
                        f"home.{jname} = {value} is outside the joint limits [{lower}, {upper}]", value_node
                    )
                home[jname] = value

        ik = IKSettings()
        if "ik" in top:
            ik = self.ik(top["ik"][1])
        scene_offset = (0.0, 0.0, 0.0)
        if "workcell" in top:
            scene_offset = self.workcell(top["workcell"][1])

        return RobotDescription(
            name=name,
            source=self.path,
            urdf_path=urdf_path,
            srdf_path=srdf_path,
            package_dirs=package_dirs,
            srdf_joint_prefix=prefix,
            base_frame=base_frame,
            arms=arms,
            head_joints=head_joints,
            head_camera=head_camera,
            home=home,
            joint_limits=limits,
            ik=ik,
            urdf=urdf,
            scene_offset=scene_offset,
        )

    def limit_margin(self, node: yaml.Node, limits: dict[str, tuple[float, float]],
                     arms: dict[str, ArmDescription], named: set[str]) -> None:
        """Keep every arm joint ``margin`` inside its URDF limits (joints ``joint_limits`` names keep theirs): IK
        then never returns a configuration on a limit, where the simulator's motors cannot hold the pose and
        the next move has no room to turn that joint."""
        margin = self.number(node, "joint_limit_margin (radians)")
        for arm in arms.values():
            for joint in arm.joints:
                lower, upper = limits[joint]
                if joint in named or not (math.isfinite(lower) and math.isfinite(upper)):
                    continue
                if margin < 0.0 or 2.0 * margin >= upper - lower:
                    raise self.error(f"joint_limit_margin {margin} must be at least 0 and leave {joint} a range "
                                     f"(its limits are [{lower}, {upper}])", node)
                limits[joint] = (lower + margin, upper - margin)

    def workcell(self, node: yaml.Node) -> tuple[float, float, float]:
        entries = self.mapping(node, "workcell")
        self.check_keys(entries, {"scene_offset"}, "workcell")
        if "scene_offset" not in entries:
            return (0.0, 0.0, 0.0)
        offset_node = entries["scene_offset"][1]
        items = self.sequence(offset_node, "workcell.scene_offset")
        if len(items) != 3:
            raise self.error("workcell.scene_offset must be [x, y, z] (metres)", offset_node)
        x, y, z = (self.number(item, "workcell.scene_offset") for item in items)
        return (x, y, z)

    def files(self, node: yaml.Node) -> tuple[Path, Path | None, tuple[Path, ...], str]:
        entries = self.mapping(node, "files")
        self.check_keys(entries, {"distribution", "share", "urdf", "srdf", "srdf_joint_prefix"}, "files")
        if "distribution" in entries:
            dist_node = entries["distribution"][1]
            dist_name = self.string(dist_node, "files.distribution")
            try:
                distribution = importlib.metadata.distribution(dist_name)
            except importlib.metadata.PackageNotFoundError:
                raise self.error(f"files.distribution: {dist_name!r} is not installed", dist_node) from None
            share_node = self.require(entries, "share", node, "files")
            share = Path(str(distribution.locate_file(self.string(share_node, "files.share"))))
        else:
            share_node = self.require(entries, "share", node, "files")
            share = self.path.parent / self.string(share_node, "files.share")
        if not share.is_dir():
            raise self.error(f"files.share: folder {share} does not exist", share_node)
        urdf_node = self.require(entries, "urdf", node, "files")
        urdf_path = share / self.string(urdf_node, "files.urdf")
        if not urdf_path.is_file():
            raise self.error(f"files.urdf: file {urdf_path} does not exist", urdf_node)
        srdf_path = None
        if "srdf" in entries:
            srdf_node = entries["srdf"][1]
            srdf_path = share / self.string(srdf_node, "files.srdf")
            if not srdf_path.is_file():
                raise self.error(f"files.srdf: file {srdf_path} does not exist", srdf_node)
        prefix = ""
        if "srdf_joint_prefix" in entries:
            prefix = self.string(entries["srdf_joint_prefix"][1], "files.srdf_joint_prefix")
        return urdf_path, srdf_path, (share,), prefix

    def arm(self, arm_name: str, node: yaml.Node, urdf: UrdfSummary) -> ArmDescription:
        what = f"arms.{arm_name}"
        entries = self.mapping(node, what)
        self.check_keys(entries, {"joints", "end_effector", "camera", "gripper", "top_down_yaw"}, what)
        joints_node = self.require(entries, "joints", node, what)
        joints = tuple(self.joint(n, f"{what}.joints", urdf) for n in self.sequence(joints_node, f"{what}.joints"))
        if not joints:
            raise self.error(f"{what}.joints: at least one joint is required", joints_node)
        if len(set(joints)) != len(joints):
            raise self.error(f"{what}.joints: a joint is listed twice", joints_node)
        end_effector = self.frame(self.require(entries, "end_effector", node, what), f"{what}.end_effector", urdf)
        camera = self.frame(entries["camera"][1], f"{what}.camera", urdf) if "camera" in entries else None
        gripper = None
        if "gripper" in entries:
            gripper = self.gripper(what + ".gripper", entries["gripper"][1], urdf)
        top_down_yaw = math.pi
        if "top_down_yaw" in entries:
            top_down_yaw = math.radians(self.number(entries["top_down_yaw"][1], f"{what}.top_down_yaw (degrees)"))
        return ArmDescription(arm_name, joints, end_effector, camera, gripper, top_down_yaw)

    def gripper(self, what: str, node: yaml.Node, urdf: UrdfSummary) -> GripperDescription:
        entries = self.mapping(node, what)
        self.check_keys(entries, {"joints", "open", "closed", "opening", "grasp", "force", "depth", "fingertip"},
                        what)
        joints_node = self.require(entries, "joints", node, what)
        joints = tuple(self.joint(n, f"{what}.joints", urdf) for n in self.sequence(joints_node, f"{what}.joints"))
        values = {}
        for key in ("open", "closed"):
            values_node = self.require(entries, key, node, what)
            items = self.sequence(values_node, f"{what}.{key}")
            if len(items) != len(joints):
                raise self.error(f"{what}.{key}: expected {len(joints)} values, one per gripper joint", values_node)
            numbers = tuple(self.number(n, f"{what}.{key}") for n in items)
            for joint, value, item in zip(joints, numbers, items, strict=True):
                lower, upper = urdf.limits[joint]
                if not lower - 1e-12 <= value <= upper + 1e-12:
                    raise self.error(f"{what}.{key}: {joint} = {value} is outside [{lower}, {upper}]", item)
            values[key] = numbers
        opening = self.number(self.require(entries, "opening", node, what), f"{what}.opening", positive=True)
        grasp = "fixed"
        if "grasp" in entries:
            grasp = self.string(entries["grasp"][1], f"{what}.grasp")
            if grasp not in ("fixed", "friction"):
                raise self.error(f"{what}.grasp must be 'fixed' or 'friction', not {grasp!r}", entries["grasp"][1])
        options = {key: self.number(entries[key][1], f"{what}.{key}", positive=key == "force")
                   for key in ("force", "depth", "fingertip") if key in entries}
        return GripperDescription(joints, values["open"], values["closed"], opening, grasp, **options)

    def ik(self, node: yaml.Node) -> IKSettings:
        entries = self.mapping(node, "ik")
        defaults = IKSettings()
        kinds = {f: type(getattr(defaults, f)) for f in defaults.__dataclass_fields__}
        self.check_keys(entries, set(kinds), "ik")
        values: dict[str, Any] = {}
        for key, (_, value_node) in entries.items():
            if kinds[key] is int:
                values[key] = self.integer(value_node, f"ik.{key}")
            else:
                values[key] = self.number(value_node, f"ik.{key}", positive=key != "lm_damping")
        at_least_one = (
            "max_iterations",
            "max_attempts",
            "stall_iterations",
            "max_colliding_solutions",
            "restart_samples",
        )
        for key in at_least_one:
            if key in values and values[key] < 1:
                raise self.error(f"ik.{key} must be at least 1", entries[key][1])
        return IKSettings(**values)
