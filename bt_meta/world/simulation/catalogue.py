"""Object types as data: the shipped catalogue (``trees/objects/catalogue.yaml``) and a user's files.

An entry gives a type's geometry (a box, a cylinder, or a mesh file: one shipped beside the catalogue or inside an
installed package such as example-robot-data), mass, default colour, friction, magnetic role, its
attachment features (the paper's AP and AN, in the object frame) and its grasp frames. Scene files name entries
by ``type:`` next to the types built in code (:data:`~bt_meta.world.simulation.objects.OBJECT_TYPES`: Mega Bloks,
magnetic parts, housing, shaft, task board, whose compound geometry stays in code), and extend the catalogue
with ``catalogue: [FILE, ...]`` (paths read beside the scene file). Every mistake is a
:class:`~bt_meta.errors.ConfigError` at ``path:line:column``; an entry without features or grasp frames is one.

Offers:

* :class:`CatalogueEntry` -- one type; ``model(colour)`` builds its
  :class:`~bt_meta.world.simulation.objects.ObjectModel`
* :func:`load_catalogue` -- the entries of one file
* :func:`shipped_catalogue` -- the shipped entries (read once)
* :func:`object_types` -- type name -> model factory: built-in code types, the shipped catalogue, then ``extra``
  files (a later file may not redefine a type)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from bt_meta.errors import ConfigError
from bt_meta.resources import trees_dir
from bt_meta.world._yaml_nodes import YamlNodeReader
from bt_meta.world.simulation.meshes import MeshError, distribution_file, read_vertices
from bt_meta.world.simulation.objects import (
    COLOURS,
    OBJECT_TYPES,
    AttachmentFeature,
    Box,
    Cylinder,
    Mesh,
    ObjectModel,
    Part,
)

__all__ = ["CatalogueEntry", "catalogue_path", "load_catalogue", "object_types", "shipped_catalogue"]

_ENTRY_KEYS = {"description", "shape", "size", "radius", "length", "mesh", "scale", "mass", "colour", "friction",
               "rolling_friction", "spinning_friction", "role", "features", "primary", "grasp_frames"}
_SHAPES = {"box": ("size",), "cylinder": ("radius", "length"), "mesh": ("mesh", "scale")}
ROLLING_FRICTION = {"cylinder": 0.001, "box": 0.0, "mesh": 0.0}
"""A type's default rolling friction, by its shape: a cylinder lying on its side rolls on the table with none (a
2.4 cm pin rolled 6 cm on its own before a gripper reached it, and off the table in 5 s; real parts stop), 0.001
holds it still. A box or a mesh (pybullet collides it as its convex hull) rests on flat faces and cannot roll: no
rolling friction, which would also slow how such a part tips over when it is turned (0.001 on every body changed a
Panda turn of a block). A catalogue entry's ``rolling_friction`` overrides it."""
SPINNING_FRICTION = 0.001
"""The default spinning (torsional) friction of every type, as the built-in ones have."""

Pose6 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class CatalogueEntry:
    name: str
    description: str
    parts: tuple[Part, ...]
    mass: float
    colour: str
    friction: float
    role: str | None
    features: tuple[AttachmentFeature, ...]
    primary: str
    grasp_frames: dict[str, Pose6]
    """Grasp frame name -> gripper pose (x, y, z in metres, roll, pitch, yaw in radians) in the object frame."""
    path: Path = field(compare=False)
    rolling_friction: float = 0.0
    spinning_friction: float = SPINNING_FRICTION

    def model(self, colour: str | None = None) -> ObjectModel:
        info = {f"grasp_{name}_{axis}": value for name, pose in self.grasp_frames.items()
                for axis, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), pose, strict=True)}
        return ObjectModel(type=self.name, colour=colour or self.colour, parts=self.parts, mass=self.mass,
                           features=self.features, primary=self.primary, role=self.role,
                           lateral_friction=self.friction, rolling_friction=self.rolling_friction,
                           spinning_friction=self.spinning_friction, info=info)


def catalogue_path() -> Path:
    return trees_dir() / "objects" / "catalogue.yaml"


@functools.cache
def shipped_catalogue() -> dict[str, CatalogueEntry]:
    return load_catalogue(catalogue_path())


def object_types(extra: Iterable[Path] = ()) -> dict[str, Callable[[str | None], ObjectModel]]:
    """Every type a scene may name: built-in code types, the shipped catalogue, then the ``extra`` files'."""
    types: dict[str, Callable[[str | None], ObjectModel]] = dict(OBJECT_TYPES)
    for name, entry in shipped_catalogue().items():
        types.setdefault(name, entry.model)
    for path in extra:
        for name, entry in load_catalogue(path).items():
            if name in types:
                raise ConfigError(f"object type {name!r} is already defined (built in or shipped); choose another "
                                  "name", path)
            types[name] = entry.model
    return types


def load_catalogue(path: str | Path) -> dict[str, CatalogueEntry]:
    """The entries of a catalogue file (``types:`` -> name -> entry)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("object catalogue file not found", path)
    return _CatalogueFile(path).load()


class _CatalogueFile(YamlNodeReader):
    def load(self) -> dict[str, CatalogueEntry]:
        try:
            root = yaml.compose(self.path.read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
        except yaml.MarkedYAMLError as error:
            mark = error.problem_mark or error.context_mark
            raise ConfigError(f"not valid YAML: {error.problem or error}", self.path,
                              mark.line + 1 if mark else None, mark.column + 1 if mark else None) from None
        if root is None:
            raise ConfigError("the object catalogue is empty", self.path, 1, 1)
        top = self.mapping(root, "an object catalogue", {"types"})
        types = self.require(top, "types", root, "an object catalogue")
        return {name: self.entry(name, node) for name, (_, node) in self.mapping(types, "types").items()}

    def entry(self, name: str, node: yaml.Node) -> CatalogueEntry:
        what = f"type {name!r}"
        entries = self.mapping(node, what, _ENTRY_KEYS)
        shape_node = self.require(entries, "shape", node, what)
        shape = self.string(shape_node, f"{what} shape")
        if shape not in _SHAPES:
            raise self.error(f"{what}: unknown shape {shape!r}; known: {', '.join(_SHAPES)}", shape_node)
        for key in ("size", "radius", "length", "mesh", "scale"):
            if key in entries and key not in _SHAPES[shape]:
                raise self.error(f"{what}: a {shape} takes {', '.join(_SHAPES[shape])}, not {key}", entries[key][0])
        part: Part
        if shape == "box":
            size = self.vector(self.require(entries, "size", node, what), f"{what} size", positive=True)
            part = Box(size)
        elif shape == "cylinder":
            part = Cylinder(self.number(self.require(entries, "radius", node, what), f"{what} radius", positive=True),
                            self.number(self.require(entries, "length", node, what), f"{what} length", positive=True))
        else:
            part = self.mesh(self.require(entries, "mesh", node, what), entries.get("scale"), what)
        mass = self.number(self.require(entries, "mass", node, what), f"{what} mass")
        if mass < 0:
            raise self.error(f"{what}: mass must be at least 0 (0: a static body)", entries["mass"][1])
        colour = "grey"
        if "colour" in entries:
            colour = self.string(entries["colour"][1], f"{what} colour")
            if colour not in COLOURS:
                raise self.error(f"{what}: unknown colour {colour!r}; known: {', '.join(COLOURS)}",
                                 entries["colour"][1])
        friction = self.number(entries["friction"][1], f"{what} friction", positive=True) if "friction" in entries \
            else 0.8
        rolling = self._not_negative(entries, "rolling_friction", ROLLING_FRICTION[shape], what)
        spinning = self._not_negative(entries, "spinning_friction", SPINNING_FRICTION, what)
        role = None
        if "role" in entries:
            role = self.string(entries["role"][1], f"{what} role")
            if role not in ("active", "reference"):
                raise self.error(f"{what}: role is 'active' or 'reference', not {role!r}", entries["role"][1])
        if "features" not in entries:
            raise self.error(f"{what}: missing key 'features' (its attachment points and normals, AP/AN)", node)
        features = []
        for feature, (_, value) in self.mapping(entries["features"][1], f"{what} features").items():
            spec = self.mapping(value, f"{what} feature {feature!r}", {"point", "normal"})
            point_node = self.require(spec, "point", value, f"feature {feature!r}")
            point = self.vector(point_node, f"feature {feature!r} point")
            normal_node = self.require(spec, "normal", value, f"feature {feature!r}")
            normal = self.vector(normal_node, f"feature {feature!r} normal")
            length = math.sqrt(sum(v * v for v in normal))
            if abs(length - 1.0) > 1e-6:
                raise self.error(f"feature {feature!r}: the normal must be a unit vector (length {length:.4f})",
                                 normal_node)
            features.append(AttachmentFeature(feature, point, normal))
        if not features:
            raise self.error(f"{what}: give at least one feature", entries["features"][1])
        primary = features[0].name
        if "primary" in entries:
            primary = self.string(entries["primary"][1], f"{what} primary")
            if primary not in {f.name for f in features}:
                raise self.error(f"{what}: primary {primary!r} is not one of its features", entries["primary"][1])
        if "grasp_frames" not in entries:
            raise self.error(f"{what}: missing key 'grasp_frames' (where a gripper may hold it)", node)
        frames: dict[str, Pose6] = {}
        for frame, (_, value) in self.mapping(entries["grasp_frames"][1], f"{what} grasp_frames").items():
            items = self.sequence(value, f"grasp frame {frame!r}")
            if len(items) != 6:
                raise self.error(f"grasp frame {frame!r} must be [x, y, z, roll, pitch, yaw] (m, degrees)", value)
            x, y, z, roll, pitch, yaw = (self.number(v, f"grasp frame {frame!r}") for v in items)
            frames[frame] = (x, y, z, math.radians(roll), math.radians(pitch), math.radians(yaw))
        if not frames:
            raise self.error(f"{what}: give at least one grasp frame", entries["grasp_frames"][1])
        description = self.string(entries["description"][1], f"{what} description") if "description" in entries \
            else ""
        return CatalogueEntry(name, description, (part,), mass, colour, friction, role, tuple(features), primary,
                              frames, self.path, rolling, spinning)

    def _not_negative(self, entries: dict[str, tuple[yaml.Node, yaml.Node]], key: str, default: float,
                      what: str) -> float:
        """The entry's ``key`` (a number, at least 0), else ``default``."""
        if key not in entries:
            return default
        value = self.number(entries[key][1], f"{what} {key}")
        if value < 0:
            raise self.error(f"{what}: {key} must be at least 0", entries[key][1])
        return value

    def mesh(self, node: yaml.Node, scale: tuple[yaml.Node, yaml.Node] | None, what: str) -> Mesh:
        """``mesh: FILE`` (beside this catalogue) or ``mesh: {distribution: NAME, path: FILE}`` (inside an
        installed package's files), scaled by ``scale: [x, y, z]`` (default 1)."""
        if isinstance(node, yaml.MappingNode):
            spec = self.mapping(node, f"{what} mesh", {"distribution", "path"})
            distribution = self.string(self.require(spec, "distribution", node, f"{what} mesh"), f"{what} mesh")
            relative = self.string(self.require(spec, "path", node, f"{what} mesh"), f"{what} mesh path")
            try:
                path = distribution_file(distribution, relative)
            except MeshError as error:
                raise self.error(f"{what}: {error}", node) from None
        else:
            path = self.path.parent / self.string(node, f"{what} mesh")
            if not path.is_file():
                raise self.error(f"{what}: mesh file {path} does not exist", node)
        factors = (1.0, 1.0, 1.0) if scale is None else self.vector(scale[1], f"{what} scale", positive=True)
        try:
            vertices = read_vertices(path) * np.array(factors)
        except MeshError as error:
            raise self.error(f"{what}: {error}", node) from None
        return Mesh(str(path.resolve()), factors, tuple(tuple(float(v) for v in row) for row in vertices))

    def vector(self, node: yaml.Node, what: str, *, positive: bool = False) -> tuple[float, float, float]:
        items = self.sequence(node, what)
        if len(items) != 3:
            raise self.error(f"{what} must be [x, y, z]", node)
        x, y, z = (self.number(v, what, positive=positive) for v in items)
        return (x, y, z)
