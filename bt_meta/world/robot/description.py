"""Robot descriptions as data: load ``robots/NAME.yaml`` and check it against the robot's URDF.

Offers:

* :func:`load_robot` -- a :class:`RobotDescription` from a shipped name (``"baxter"``) or a YAML path
* :class:`RobotDescription` -- model files, arms, cameras, home pose, joint limits (``joint_limit_margin`` keeps IK
  off the URDF limits), IK settings, the workcell offset
* :class:`ArmDescription`, :class:`GripperDescription` (how the simulator grasps: ``fixed`` or ``friction``),
  :class:`IKSettings` -- its parts
* :class:`UrdfSummary` / :func:`read_urdf_summary` -- joint and link names, types and limits of a URDF
* :class:`AddedFrame` -- a fixed frame the description adds to its URDF (a tool centre point, a camera mount):
  every model (Pinocchio, MuJoCo, pybullet) then loads the same derived URDF, written once per content

A wrong robot file raises :class:`~bt_meta.errors.ConfigError` located at the offending YAML node
(``path:line:column``): a missing key, a wrong type, or a joint or frame that the URDF does not have; a URDF
that does not load (not XML, a joint naming a link it lacks, a mesh that is not there) is located in the URDF.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import math
import os
import tempfile
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.parsers import expat

import yaml

from bt_meta.errors import ConfigError, KinematicsError
from bt_meta.model_cache import cached, clear_entry, file_signature
from bt_meta.resources import robots_dir
from bt_meta.world._yaml_nodes import YamlNodeReader, shipped_yaml_path

__all__ = [
    "AddedFrame",
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
    closing_axis: tuple[float, float, float] | None = None
    """Unit vector, in the end-effector frame, across the fingers (the first finger's opening direction): given for
    a gripper whose fingers do not move (no ``joints``), else read from the first finger joint's axis."""
    turn_about_fingers: bool = False
    """A part being re-oriented is turned about the fingers' closing axis (a part on its side grasped across the
    axis it turns about; an upside-down one flipped about the fingers): a hand long across its fingers (the
    Panda's) stays level instead of reaching down into the table."""


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
class AddedFrame:
    """A fixed frame the robot file adds to the URDF: ``xyz`` (m) and ``rpy`` (rad) in its ``parent`` link."""

    name: str
    parent: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]


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
    added_frames: tuple[AddedFrame, ...] = ()
    """Fixed frames the file adds to the URDF; ``urdf_path`` is then a derived copy that has them."""
    source_urdf_path: Path | None = None
    """The URDF the file names (``urdf_path`` is derived from it when frames are added)."""

    def scene_to_base(self, point: tuple[float, float, float] | list[float]) -> tuple[float, float, float]:
        """A point of the scene frame in this robot's base frame."""
        return tuple(float(v) + d for v, d in zip(point, self.scene_offset, strict=True))  # type: ignore[return-value]

    def base_to_scene(self, point: tuple[float, float, float] | list[float]) -> tuple[float, float, float]:
        """A point of this robot's base frame in the scene frame."""
        return tuple(float(v) - d for v, d in zip(point, self.scene_offset, strict=True))  # type: ignore[return-value]

    def frames(self) -> dict[str, Any]:
        """What an output's poses are in: the robot's base frame, and how the scene frame relates to it."""
        return {"poses": "base", "base_frame": self.base_frame, "scene_offset": list(self.scene_offset),
                "scene_to_base": "base = scene + scene_offset (no rotation)"}

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
    urdf = description.source_urdf_path or description.urdf_path
    return (file_signature(urdf), file_signature(description.srdf_path), description.urdf_path.is_file())


# --------------------------------------------------------------------------------------------------------------
# URDF


def read_urdf_summary(path: Path, package_dirs: tuple[Path, ...] = ()) -> UrdfSummary:
    """Names, types, limits and mimic relations of a URDF, checked so that the models load it: every joint joins
    two links the file has, every link but one (the root) has a parent, and every mesh file exists (``package://``
    URIs under ``package_dirs``, when given). Errors are located at the element (``path:line:column``)."""
    text = path.read_text(encoding="utf-8")
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise ConfigError("URDF files with a DOCTYPE or entities are not accepted", path)
    root, where = _located_xml(text, path)
    if root.tag != "robot":
        raise ConfigError(f"URDF root element is <{root.tag}>, expected <robot>", path, 1)

    def error(message: str, element: ElementTree.Element) -> ConfigError:
        line, column = where.get(id(element), (1, 1))
        return ConfigError(message, path, line, column)

    links = tuple(el.get("name", "") for el in root.findall("link"))
    for el in root.findall("link"):
        if not el.get("name"):
            raise error("a <link> has no name", el)
    if len(set(links)) != len(links):
        twice = next(el for i, el in enumerate(root.findall("link")) if el.get("name") in links[:i])
        raise error(f"link {twice.get('name')!r} is defined twice", twice)
    joints: dict[str, str] = {}
    limits: dict[str, tuple[float, float]] = {}
    mimic: dict[str, tuple[str, float, float]] = {}
    parent_of: dict[str, str] = {}
    for el in root.findall("joint"):
        jname, kind = el.get("name", ""), el.get("type", "")
        if not jname or jname in joints:
            raise error(f"a <joint> has no name or repeats one ({jname!r})", el)
        if kind not in ("revolute", "continuous", "prismatic", "fixed", "floating", "planar"):
            raise error(f"joint {jname!r} has an unknown type {kind!r}", el)
        for end in ("parent", "child"):
            link_el = el.find(end)
            link = link_el.get("link", "") if link_el is not None else ""
            if link not in links:
                raise error(f"joint {jname!r}: its {end} link {link!r} is not in the URDF", el)
        child = el.find("child").get("link", "")  # type: ignore[union-attr]
        if child in parent_of:
            raise error(f"joint {jname!r}: link {child!r} already has a parent joint", el)
        parent_of[child] = el.find("parent").get("link", "")  # type: ignore[union-attr]
        joints[jname] = kind
        if kind == "continuous":
            limits[jname] = (-math.inf, math.inf)
        elif kind in ("revolute", "prismatic"):
            limit = el.find("limit")
            try:
                lower = float(limit.get("lower", "0")) if limit is not None else 0.0
                upper = float(limit.get("upper", "0")) if limit is not None else 0.0
            except ValueError:
                raise error(f"joint {jname!r}: its limits are not numbers", limit) from None
            limits[jname] = (lower, upper)
        m = el.find("mimic")
        if m is not None:
            mimic[jname] = (m.get("joint", ""), float(m.get("multiplier", "1")), float(m.get("offset", "0")))
    roots = [link for link in links if link not in parent_of]
    if links and len(roots) != 1:
        raise error(f"the links do not form one tree: {len(roots)} have no parent joint ({', '.join(roots[:4])})",
                    root)
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        if filename.startswith("package://") and not package_dirs:
            continue
        if filename and _mesh_file(filename, path, package_dirs) is None:
            raise error(f"mesh file {filename!r} is not there", mesh)
    return UrdfSummary(root.get("name", ""), links, joints, limits, mimic)


def _mesh_file(filename: str, urdf: Path, package_dirs: tuple[Path, ...]) -> Path | None:
    """The file a URDF mesh reference names, ``None`` when there is none."""
    if filename.startswith("package://"):
        relative = filename[len("package://"):]
        return next((Path(base) / relative for base in package_dirs if (Path(base) / relative).is_file()), None)
    local = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
    local = local if local.is_absolute() else urdf.parent / local
    return local if local.is_file() else None


def _located_xml(text: str, path: Path) -> tuple[ElementTree.Element, dict[int, tuple[int, int]]]:
    """The parsed XML and, per element (by id), where its start tag is (line, column)."""
    where: dict[int, tuple[int, int]] = {}
    builder = ElementTree.TreeBuilder()
    parser = expat.ParserCreate()

    def start(tag: str, attrs: dict[str, str]) -> None:
        element = builder.start(tag, attrs)
        where[id(element)] = (parser.CurrentLineNumber, parser.CurrentColumnNumber + 1)

    parser.StartElementHandler = start
    parser.EndElementHandler = builder.end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as error:
        raise ConfigError(f"URDF is not well-formed XML: {expat.ErrorString(error.code)}: line {error.lineno}, "
                          f"column {error.offset}", path, error.lineno, error.offset + 1) from None
    return builder.close(), where


def _urdf_with_frames(source: Path, frames: tuple[AddedFrame, ...]) -> Path:
    """A copy of ``source`` with ``frames`` added as massless links on fixed joints, local mesh paths made
    absolute; written once per content (the name is its digest) where every process finds it."""
    root = ElementTree.fromstring(source.read_text(encoding="utf-8"))
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        if filename and "://" not in filename and not Path(filename).is_absolute():
            mesh.set("filename", str(source.parent / filename))
    for frame in frames:
        link = ElementTree.SubElement(root, "link", {"name": frame.name})
        inertial = ElementTree.SubElement(link, "inertial")
        ElementTree.SubElement(inertial, "mass", {"value": "0"})
        ElementTree.SubElement(inertial, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
        ElementTree.SubElement(inertial, "inertia", {k: "0" for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")})
        joint = ElementTree.SubElement(root, "joint", {"name": f"{frame.name}_fixed_joint", "type": "fixed"})
        ElementTree.SubElement(joint, "parent", {"link": frame.parent})
        ElementTree.SubElement(joint, "child", {"link": frame.name})
        ElementTree.SubElement(joint, "origin", {"xyz": " ".join(repr(v) for v in frame.xyz),
                                                 "rpy": " ".join(repr(v) for v in frame.rpy)})
    text = ElementTree.tostring(root, encoding="unicode")
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
    folder = Path(tempfile.gettempdir()) / "bt_meta_robot_models"
    out = folder / f"{source.stem}-{digest}.urdf"
    if not out.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        partial = folder / f".{out.name}.{os.getpid()}"
        partial.write_text(text, encoding="utf-8")
        os.replace(partial, out)  # atomic: a process reading it never sees half a file
    return out


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
            {"name", "files", "added_frames", "base_frame", "arms", "head", "home", "joint_limits",
             "joint_limit_margin", "ik", "workcell"},
            "robot description",
        )
        name = self.string(self.require(top, "name", root, "robot description"), "name")

        files_node = self.require(top, "files", root, "robot description")
        urdf_path, srdf_path, package_dirs, prefix = self.files(files_node)
        urdf = read_urdf_summary(urdf_path, package_dirs)
        source_urdf = urdf_path
        added: tuple[AddedFrame, ...] = ()
        if "added_frames" in top:
            added = self.added_frames(top["added_frames"][1], urdf)
            urdf = dataclasses.replace(
                urdf, links=urdf.links + tuple(f.name for f in added),
                joints={**urdf.joints, **{f"{f.name}_fixed_joint": "fixed" for f in added}})
            urdf_path = _urdf_with_frames(source_urdf, added)

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
            added_frames=added,
            source_urdf_path=source_urdf,
        )

    def added_frames(self, node: yaml.Node, urdf: UrdfSummary) -> tuple[AddedFrame, ...]:
        """``added_frames: {NAME: {parent: LINK, xyz: [m, m, m], rpy: [deg, deg, deg]}}``: frames the URDF lacks."""
        out: list[AddedFrame] = []
        for name, (key_node, value_node) in self.mapping(node, "added_frames").items():
            what = f"added_frames.{name}"
            if name in urdf.frames or f"{name}_fixed_joint" in urdf.frames:
                raise self.error(f"{what}: the URDF already has a link or joint named {name!r}", key_node)
            entries = self.mapping(value_node, what)
            self.check_keys(entries, {"parent", "xyz", "rpy"}, what)
            parent_node = self.require(entries, "parent", value_node, what)
            parent = self.string(parent_node, f"{what}.parent")
            if parent not in urdf.links and parent not in {f.name for f in out}:
                raise self.error(f"{what}.parent: unknown link {parent!r} (not in the URDF)", parent_node)
            triples = {}
            for key in ("xyz", "rpy"):
                triples[key] = (0.0, 0.0, 0.0)
                if key in entries:
                    items = self.sequence(entries[key][1], f"{what}.{key}")
                    if len(items) != 3:
                        raise self.error(f"{what}.{key} must be three numbers", entries[key][1])
                    triples[key] = tuple(self.number(item, f"{what}.{key}") for item in items)
            rpy = tuple(math.radians(v) for v in triples["rpy"])
            out.append(AddedFrame(name, parent, triples["xyz"], rpy))  # type: ignore[arg-type]
        return tuple(out)

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
        self.check_keys(entries, {"joints", "open", "closed", "opening", "grasp", "force", "depth", "fingertip",
                                  "closing_axis", "turn_about_fingers"}, what)
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
        options: dict[str, Any] = {key: self.number(entries[key][1], f"{what}.{key}", positive=key == "force")
                                   for key in ("force", "depth", "fingertip") if key in entries}
        if "closing_axis" in entries:
            axis_node = entries["closing_axis"][1]
            items = self.sequence(axis_node, f"{what}.closing_axis")
            axis = [self.number(item, f"{what}.closing_axis") for item in items]
            norm = math.sqrt(sum(v * v for v in axis))
            if len(axis) != 3 or norm < 1e-9:
                raise self.error(f"{what}.closing_axis must be three numbers, not all zero", axis_node)
            options["closing_axis"] = tuple(v / norm for v in axis)
        elif not joints:
            raise self.error(f"{what}: a gripper without finger joints needs closing_axis (in the end-effector "
                             "frame)", node)
        if "turn_about_fingers" in entries:
            flag = self.scalar(entries["turn_about_fingers"][1], f"{what}.turn_about_fingers")
            if not isinstance(flag, bool):
                raise self.error(f"{what}.turn_about_fingers must be true or false", entries["turn_about_fingers"][1])
            options["turn_about_fingers"] = flag
        if not joints and grasp == "friction":
            raise self.error(f"{what}.grasp: a friction grasp needs finger joints", entries["grasp"][1])
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
