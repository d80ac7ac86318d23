"""Object models of the paper's scenes as data: geometry, colour, mass and attachment features.

A model is a compound of boxes and cylinders in the object frame (origin = centre of mass), plus named
attachment features (a point AP and an outward unit normal AN, object frame). The simulator builds bodies
from models; perception and the meta-reasoner read the same features back in the robot base frame.

Offers:

* :data:`LB` -- the Mega Bloks unit, 6.1 cm
* :class:`Box`, :class:`Cylinder`, :class:`Mesh` -- the primitive parts of a model
* :class:`AttachmentFeature` -- a named attachment point and normal in the object frame
* :class:`ObjectModel` -- one kind of object (type, colour, parts, mass, features, primary feature, role)
* :func:`megablok`, :func:`magnetic_part`, :func:`task_board`, :func:`housing`, :func:`shaft` -- the paper's objects
* :func:`make_model` / :data:`OBJECT_TYPES` / :data:`COLOURS` -- build a model from a type name and a colour name
* :class:`AttachmentRelation` / :func:`attachment_relation` -- the magnetic attach rule (points coincide, normals
  oppose) and the paper's R_p, R_n keypoint relations
* :func:`pose_to_matrix`, :func:`matrix_to_pose`, :func:`rpy_to_matrix` -- (x, y, z, roll, pitch, yaw) poses,
  from :mod:`bt_meta.world.poses` (kept here for the modules that import them from here)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from bt_meta.errors import BtMetaError
from bt_meta.world.poses import Pose6, matrix_to_pose, pose_to_matrix, rpy_to_matrix

__all__ = [
    "COLOURS",
    "LB",
    "OBJECT_TYPES",
    "AttachmentFeature",
    "AttachmentRelation",
    "Box",
    "Cylinder",
    "Mesh",
    "ObjectModel",
    "ObjectModelError",
    "Pose6",
    "attachment_relation",
    "housing",
    "magnetic_part",
    "make_model",
    "matrix_to_pose",
    "megablok",
    "pose_to_matrix",
    "rpy_to_matrix",
    "shaft",
    "task_board",
]

LB = 0.061
"""One Mega Bloks unit (m): a 1x1 block is LB x LB in plan (paper, section 6.1)."""

Vec3 = tuple[float, float, float]

COLOURS: dict[str, tuple[float, float, float, float]] = {
    "red": (0.85, 0.08, 0.08, 1.0),
    "blue": (0.08, 0.2, 0.85, 1.0),
    "green": (0.1, 0.65, 0.2, 1.0),
    "yellow": (0.95, 0.8, 0.1, 1.0),
    "orange": (0.95, 0.45, 0.05, 1.0),
    "grey": (0.55, 0.55, 0.55, 1.0),
    "dark_grey": (0.3, 0.3, 0.32, 1.0),
    "white": (0.92, 0.92, 0.92, 1.0),
    "black": (0.05, 0.05, 0.05, 1.0),
}
"""Colour names usable in scene files -> RGBA. Blocks in the paper are red and blue."""


class ObjectModelError(BtMetaError):
    """An object type or colour that does not exist, or a model built with impossible dimensions."""


# --------------------------------------------------------------------------------------------------------------
# Models


@dataclass(frozen=True)
class Box:
    """A box part: full ``size`` (m) centred at ``position`` and turned by ``rpy`` in the object frame."""

    size: Vec3
    position: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)

    def corners(self) -> np.ndarray:
        half = np.array(self.size) / 2.0
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return signs * half @ rpy_to_matrix(*self.rpy).T + np.array(self.position)


@dataclass(frozen=True)
class Cylinder:
    """A cylinder part along its local z: ``radius``, full ``length``, at ``position`` turned by ``rpy``."""

    radius: float
    length: float
    position: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)

    def corners(self, samples: int = 32) -> np.ndarray:
        """Points on both rims: enough for lowest-point and extent computations."""
        angles = np.linspace(0.0, 2.0 * math.pi, samples, endpoint=False)
        rim = np.stack([self.radius * np.cos(angles), self.radius * np.sin(angles)], axis=1)
        pts = np.concatenate(
            [np.column_stack([rim, np.full(samples, z)]) for z in (-self.length / 2.0, self.length / 2.0)]
        )
        return pts @ rpy_to_matrix(*self.rpy).T + np.array(self.position)


@dataclass(frozen=True)
class Mesh:
    """A mesh part: the OBJ/STL ``file`` (absolute) scaled by ``scale``, at ``position`` turned by ``rpy``.
    ``vertices`` are the file's, scaled (mesh frame): the outline everything else computes from."""

    file: str
    scale: Vec3
    vertices: tuple[Vec3, ...] = field(repr=False)
    position: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)

    def corners(self) -> np.ndarray:
        return np.array(self.vertices, dtype=float) @ rpy_to_matrix(*self.rpy).T + np.array(self.position)


Part = Box | Cylinder | Mesh


@dataclass(frozen=True)
class AttachmentFeature:
    """An attachment point (m) and its outward unit normal, both in the object frame."""

    name: str
    point: Vec3
    normal: Vec3

    def __post_init__(self) -> None:
        n = np.asarray(self.normal, dtype=float)
        length = float(np.linalg.norm(n))
        if length < 1e-9:
            raise ObjectModelError(f"attachment feature {self.name!r}: the normal is zero")
        object.__setattr__(self, "normal", tuple(float(v) for v in n / length))
        object.__setattr__(self, "point", tuple(float(v) for v in self.point))


@dataclass(frozen=True)
class ObjectModel:
    """One kind of object. ``type`` is the name scene files use; ``primary`` names the feature reported as AP/AN.

    ``mass`` 0 makes a static body (the task board). ``role`` is ``"active"`` or ``"reference"`` for magnetic
    parts (the simulator joins an active and a reference part when their primary features meet), else ``None``.
    """

    type: str
    colour: str
    parts: tuple[Part, ...]
    mass: float
    features: tuple[AttachmentFeature, ...]
    primary: str
    role: str | None = None
    shape: str | None = None
    """Paper-level shape label, e.g. ``"1x2"`` for blocks; ``None`` for other objects."""
    lateral_friction: float = 0.8
    rolling_friction: float = 0.0
    """Bullet's rolling friction of the body's contacts: what stops a round part lying on its side from rolling
    away on its own (0: a part that rests on flat faces, which cannot roll; see the catalogue's default)."""
    spinning_friction: float = 0.001
    """Bullet's spinning (torsional) friction: a part turning about the contact normal slows down."""
    info: dict[str, float] = field(default_factory=dict, compare=False)
    """Named dimensions (m) that perception and skills may want (e.g. ``body_height``, ``hole_radius``)."""

    def __post_init__(self) -> None:
        if self.colour not in COLOURS:
            raise ObjectModelError(f"unknown colour {self.colour!r}; known: {', '.join(COLOURS)}")
        names = [f.name for f in self.features]
        if len(set(names)) != len(names):
            raise ObjectModelError(f"{self.type}: duplicate attachment feature names {names}")
        if self.primary not in names:
            raise ObjectModelError(f"{self.type}: primary feature {self.primary!r} is not one of {names}")
        if self.role not in (None, "active", "reference"):
            raise ObjectModelError(f"{self.type}: role must be 'active', 'reference' or None, got {self.role!r}")

    @property
    def rgba(self) -> tuple[float, float, float, float]:
        return COLOURS[self.colour]

    def feature(self, name: str | None = None) -> AttachmentFeature:
        """The named feature, or the primary one."""
        wanted = self.primary if name is None else name
        for f in self.features:
            if f.name == wanted:
                return f
        raise ObjectModelError(f"{self.type} has no attachment feature {wanted!r}; it has {self.feature_names}")

    @property
    def feature_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.features)

    def points(self) -> np.ndarray:
        """Sample points on the geometry's outline (object frame). Computed once: the model is immutable and skills
        ask for them hundreds of times a step; the array is read-only."""
        cached = self.__dict__.get("_points")
        if cached is None:
            cached = np.concatenate([p.corners() for p in self.parts])
            cached.setflags(write=False)
            object.__setattr__(self, "_points", cached)
        return cached

    def lowest_z(self, roll: float, pitch: float) -> float:
        """How far below the origin the geometry reaches when turned by (roll, pitch): resting height on a plane."""
        rotated = self.points() @ rpy_to_matrix(roll, pitch, 0.0).T
        return float(-rotated[:, 2].min())

    def grasp_frames(self) -> list[Pose6]:
        """The model's grasp frames (catalogue types give them): gripper poses in the object frame, radians."""
        names = [key[len("grasp_"):-len("_x")] for key in self.info if key.startswith("grasp_") and key.endswith("_x")]
        return [tuple(self.info[f"grasp_{name}_{axis}"] for axis in ("x", "y", "z", "roll", "pitch", "yaw"))
                for name in names]  # type: ignore[misc]

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (min, max) of the geometry in the object frame (computed once, read-only)."""
        cached = self.__dict__.get("_extent")
        if cached is None:
            pts = self.points()
            cached = (pts.min(axis=0), pts.max(axis=0))
            for bound in cached:
                bound.setflags(write=False)
            object.__setattr__(self, "_extent", cached)
        return cached


# -- the paper's objects ---------------------------------------------------------------------------------------

_BLOCK_BODY_HEIGHT = 0.6 * LB
_STUD_RADIUS = 0.3 * LB
_STUD_HEIGHT = 0.2 * LB


def megablok(shape: str, colour: str) -> ObjectModel:
    """A Mega Blok, ``"1x1"`` or ``"1x2"``: LB-pitch body 0.6 LB high with one stud per unit on top.

    The long side of a 1x2 is the object x axis. The origin is the body centre; features: ``bottom`` (primary,
    normal -z), ``top`` (on the studs, +z), and the four side faces ``side_px/nx/py/ny``.
    """
    units = {"1x1": 1, "1x2": 2}.get(shape)
    if units is None:
        raise ObjectModelError(f"a Mega Blok is 1x1 or 1x2, not {shape!r}")
    length = units * LB
    h = _BLOCK_BODY_HEIGHT
    parts: list[Part] = [Box((length, LB, h))]
    for i in range(units):
        x = (i - (units - 1) / 2.0) * LB
        parts.append(Cylinder(_STUD_RADIUS, _STUD_HEIGHT, (x, 0.0, h / 2.0 + _STUD_HEIGHT / 2.0)))
    features = (
        AttachmentFeature("bottom", (0.0, 0.0, -h / 2.0), (0.0, 0.0, -1.0)),
        AttachmentFeature("top", (0.0, 0.0, h / 2.0 + _STUD_HEIGHT), (0.0, 0.0, 1.0)),
        AttachmentFeature("side_px", (length / 2.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
        AttachmentFeature("side_nx", (-length / 2.0, 0.0, 0.0), (-1.0, 0.0, 0.0)),
        AttachmentFeature("side_py", (0.0, LB / 2.0, 0.0), (0.0, 1.0, 0.0)),
        AttachmentFeature("side_ny", (0.0, -LB / 2.0, 0.0), (0.0, -1.0, 0.0)),
    )
    return ObjectModel(
        type=f"megablok_{shape}",
        colour=colour,
        parts=tuple(parts),
        mass=0.02 * units,
        features=features,
        primary="bottom",
        shape=shape,
        info={"length": length, "width": LB, "body_height": h, "stud_height": _STUD_HEIGHT},
    )


def magnetic_part(role: str, colour: str | None = None) -> ObjectModel:
    """A magnetic-attach part: the ``active`` one is carried onto the ``reference`` one (paper, section 7).

    Active: a 4 x 4 x 6 cm block (it fits the 4.62 cm gripper) with its magnet on the bottom face, normal -z.
    Reference: a 10 x 10 x 4 cm base with its magnet on the top face, normal +z. Both are loose (mass > 0), so
    lifting an attached active part lifts the reference with it -- the paper's staging-pose verification.
    """
    if role == "active":
        size = (0.04, 0.04, 0.06)
        feature = AttachmentFeature("magnet", (0.0, 0.0, -size[2] / 2.0), (0.0, 0.0, -1.0))
        mass, default = 0.05, "yellow"
    elif role == "reference":
        size = (0.10, 0.10, 0.04)
        feature = AttachmentFeature("magnet", (0.0, 0.0, size[2] / 2.0), (0.0, 0.0, 1.0))
        mass, default = 0.2, "green"
    else:
        raise ObjectModelError(f"a magnetic part is 'active' or 'reference', not {role!r}")
    return ObjectModel(
        type=f"magnet_{role}",
        colour=colour or default,
        parts=(Box(size),),
        mass=mass,
        features=(feature,),
        primary="magnet",
        role=role,
        info={"size_x": size[0], "size_y": size[1], "size_z": size[2]},
    )


def _tube(outer: float, inner: float, length: float, z: float, segments: int = 12) -> list[Part]:
    """A polygonal tube of boxes around the z axis: a hollow cylinder from convex parts."""
    thickness = outer - inner
    width = 2.0 * outer * math.tan(math.pi / segments)
    parts: list[Part] = []
    for k in range(segments):
        a = 2.0 * math.pi * k / segments
        r = inner + thickness / 2.0
        parts.append(Box((thickness, width, length), (r * math.cos(a), r * math.sin(a), z), (0.0, 0.0, a)))
    return parts


HOUSING_BODY_RADIUS = 0.02
HOUSING_FLANGE_RADIUS = 0.035
HOUSING_BORE_RADIUS = 0.009
HOUSING_BODY_LENGTH = 0.05
HOUSING_FLANGE_THICKNESS = 0.012
BOARD_HOLE_HALF = 0.023
SHAFT_RADIUS = 0.007
SHAFT_LENGTH = 0.08


def housing(colour: str | None = None) -> ObjectModel:
    """Cylindrical housing (paper, Figures 1-3): a narrow body that fits the board's hole, a wide flange at the
    +z end that does not, and a central bore for the shaft.

    Features: ``insert_end`` (primary; the narrow end, normal -z) and ``bore`` (the bore's mouth on the flange
    face, normal +z). Upright (roll 0) the flange is on top: a top grasp and a straight insertion work;
    upside down the flange meets the board first.
    """
    total = HOUSING_BODY_LENGTH + HOUSING_FLANGE_THICKNESS
    z_body = -total / 2.0 + HOUSING_BODY_LENGTH / 2.0
    z_flange = total / 2.0 - HOUSING_FLANGE_THICKNESS / 2.0
    parts = _tube(HOUSING_BODY_RADIUS, HOUSING_BORE_RADIUS, HOUSING_BODY_LENGTH, z_body)
    parts += _tube(HOUSING_FLANGE_RADIUS, HOUSING_BORE_RADIUS, HOUSING_FLANGE_THICKNESS, z_flange)
    return ObjectModel(
        type="housing",
        colour=colour or "orange",
        parts=tuple(parts),
        mass=0.05,
        features=(
            AttachmentFeature("insert_end", (0.0, 0.0, -total / 2.0), (0.0, 0.0, -1.0)),
            AttachmentFeature("bore", (0.0, 0.0, total / 2.0), (0.0, 0.0, 1.0)),
        ),
        primary="insert_end",
        info={
            "body_radius": HOUSING_BODY_RADIUS,
            "flange_radius": HOUSING_FLANGE_RADIUS,
            "bore_radius": HOUSING_BORE_RADIUS,
            "length": total,
            "flange_thickness": HOUSING_FLANGE_THICKNESS,
        },
    )


def shaft(colour: str | None = None) -> ObjectModel:
    """A shaft that fits the housing's bore: a hexagonal prism (three boxes; it does not roll when lying down).

    Features: ``tip`` (primary, normal -z) and ``head`` (+z).
    """
    apothem = SHAFT_RADIUS * math.sqrt(3.0) / 2.0
    parts = tuple(Box((SHAFT_RADIUS, 2.0 * apothem, SHAFT_LENGTH), rpy=(0.0, 0.0, k * math.pi / 3.0)) for k in range(3))
    return ObjectModel(
        type="shaft",
        colour=colour or "grey",
        parts=parts,
        mass=0.02,
        features=(
            AttachmentFeature("tip", (0.0, 0.0, -SHAFT_LENGTH / 2.0), (0.0, 0.0, -1.0)),
            AttachmentFeature("head", (0.0, 0.0, SHAFT_LENGTH / 2.0), (0.0, 0.0, 1.0)),
        ),
        primary="tip",
        info={"radius": SHAFT_RADIUS, "length": SHAFT_LENGTH},
    )


def task_board(colour: str | None = None) -> ObjectModel:
    """A static task board: a 30 x 20 x 1.5 cm plate with a socket (4 cm high walls) around a square hole
    4.6 cm wide -- the housing's body (4 cm) fits, its flange (7 cm) does not.

    Feature ``hole`` (primary): the bottom centre of the hole, normal +z (out of the hole).
    """
    plate_h, wall_h, outer = 0.015, 0.04, 0.10
    half = BOARD_HOLE_HALF
    wall_t = outer / 2.0 - half
    zc = plate_h / 2.0 + wall_h / 2.0
    off = half + wall_t / 2.0
    parts: tuple[Part, ...] = (
        Box((0.30, 0.20, plate_h)),
        Box((outer, wall_t, wall_h), (0.0, off, zc)),
        Box((outer, wall_t, wall_h), (0.0, -off, zc)),
        Box((wall_t, 2.0 * half, wall_h), (off, 0.0, zc)),
        Box((wall_t, 2.0 * half, wall_h), (-off, 0.0, zc)),
    )
    return ObjectModel(
        type="task_board",
        colour=colour or "dark_grey",
        parts=parts,
        mass=0.0,
        features=(AttachmentFeature("hole", (0.0, 0.0, plate_h / 2.0), (0.0, 0.0, 1.0)),),
        primary="hole",
        info={"plate_height": plate_h, "socket_height": wall_h, "hole_half_width": half},
    )


OBJECT_TYPES: dict[str, Callable[[str | None], ObjectModel]] = {
    "megablok_1x1": lambda colour: megablok("1x1", colour or "red"),
    "megablok_1x2": lambda colour: megablok("1x2", colour or "red"),
    "magnet_active": lambda colour: magnetic_part("active", colour),
    "magnet_reference": lambda colour: magnetic_part("reference", colour),
    "housing": housing,
    "shaft": shaft,
    "task_board": task_board,
}
"""Type names used in scene files -> model factory taking an optional colour name."""


def make_model(type_name: str, colour: str | None = None) -> ObjectModel:
    """The model for a scene file's ``type`` and ``colour`` (``None``: the type's default colour)."""
    factory = OBJECT_TYPES.get(type_name)
    if factory is None:
        raise ObjectModelError(f"unknown object type {type_name!r}; known: {', '.join(OBJECT_TYPES)}")
    if colour is not None and colour not in COLOURS:
        raise ObjectModelError(f"unknown colour {colour!r}; known: {', '.join(COLOURS)}")
    return factory(colour)


# --------------------------------------------------------------------------------------------------------------
# The attach rule


@dataclass(frozen=True)
class AttachmentRelation:
    """R_p (distance between the attachment points, m) and R_n (angle between the normals, rad) of two objects,
    and whether the attach rule holds: R_p <= position tolerance and R_n within the angle tolerance of pi."""

    distance: float
    angle: float
    aligned: bool


def attachment_relation(
    ap_active: Sequence[float],
    an_active: Sequence[float],
    ap_reference: Sequence[float],
    an_reference: Sequence[float],
    *,
    position_tolerance: float = 0.01,
    angle_tolerance: float = math.radians(15.0),
) -> AttachmentRelation:
    """The paper's keypoint relations (section 7.4) for points and normals given in one common frame."""
    distance = float(np.linalg.norm(np.asarray(ap_active, float) - np.asarray(ap_reference, float)))
    cos = float(np.dot(an_active, an_reference) / (np.linalg.norm(an_active) * np.linalg.norm(an_reference)))
    angle = math.acos(max(-1.0, min(1.0, cos)))
    aligned = distance <= position_tolerance and (math.pi - angle) <= angle_tolerance
    return AttachmentRelation(distance, angle, aligned)
