"""Scenes and their variants as data: which objects lie where on the table, read from ``trees/scenes/*.yaml``.

A scene file names the scene, lists its objects (name, type, colour, pose; types from the built-in ones and the
object catalogue, :mod:`~bt_meta.world.simulation.catalogue`, which ``catalogue: [FILE]`` extends) and its
variants; a variant changes the nominal object list by ``override`` (new colour/type/pose for a named object),
``remove``, ``replace`` (one object by others, e.g. a 1x2 block by two 1x1s), ``add`` and ``obstacles`` (static
obstacles added: see :mod:`~bt_meta.world.simulation.obstacles`; a scene lists its own under ``obstacles:``). Poses
are
``[x, y, z, roll, pitch, yaw]`` in the scene frame (the robot base frame moved by the robot's
``workcell.scene_offset``), metres and **degrees** (people write 90, not 1.5708); ``z`` may be ``table``: resting on
the table top in that orientation. Every mistake is a :class:`~bt_meta.errors.ConfigError` at ``path:line:column``.

Offers:

* :func:`load_scene` -- a :class:`Scene` by shipped name (``"letters_A"``) or path
* :func:`scene_names` / :func:`scenes_dir` -- the shipped scenes
* :class:`Scene` -- ``objects_for(variant)``, ``build(sim, variant, seed)``, ``variant_names``
* :class:`SceneObject` -- one object's name, type, colour, pose, and where the file says so
* :class:`Variant` -- a variant's name, description and resolved object and obstacle lists
* :class:`SceneObstacle` -- one static obstacle: name, shape, model, pose, and where the file says so
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from bt_meta.errors import ConfigError
from bt_meta.resources import trees_dir
from bt_meta.world._yaml_nodes import YamlNodeReader, shipped_yaml_path
from bt_meta.world.simulation.catalogue import object_types
from bt_meta.world.simulation.objects import COLOURS, ObjectModel, make_model, pose_to_matrix
from bt_meta.world.simulation.obstacles import OBSTACLE_SHAPES, ObstacleError, obstacle_model

__all__ = ["Scene", "SceneObject", "SceneObstacle", "Variant", "load_scene", "scene_names", "scenes_dir"]

_SCENE_KEYS = {"scene", "description", "objects", "variants", "jitter", "anchors", "obstacles", "catalogue"}
_OBSTACLE_KEYS = {"name", "shape", "pose", "colour", "description", "size", "radius", "height", "thickness"}
_OBJECT_KEYS = {"name", "type", "colour", "pose", "description"}
_VARIANT_KEYS = {"description", "override", "remove", "replace", "add", "obstacles"}
_OVERRIDE_KEYS = {"type", "colour", "pose"}
_JITTER_KEYS = {"position", "yaw"}


@dataclass(frozen=True)
class Location:
    path: str
    line: int
    column: int

    def error(self, message: str) -> ConfigError:
        return ConfigError(message, self.path, self.line, self.column)


@dataclass(frozen=True)
class SceneObject:
    """One object of a scene. ``pose`` is in metres and radians; ``z`` is ``None`` for "resting on the table"."""

    name: str
    type: str
    colour: str | None
    position: tuple[float, float, float | None]
    rpy: tuple[float, float, float]
    location: Location | None = field(default=None, compare=False)
    factory: Callable[[str | None], ObjectModel] | None = field(default=None, compare=False, repr=False)
    """What builds the model: the type's entry in the scene's catalogue (built-in types when ``None``)."""

    def model(self) -> ObjectModel:
        if self.factory is not None:
            return self.factory(self.colour)
        return make_model(self.type, self.colour)

    @property
    def on_table(self) -> bool:
        return self.position[2] is None

    def pose(self) -> tuple[float, float, float, float, float, float]:
        """The pose with ``z`` 0 when it rests on the table (the simulator then computes it)."""
        x, y, z = self.position
        return (x, y, 0.0 if z is None else z, *self.rpy)


@dataclass(frozen=True)
class SceneObstacle:
    """A static obstacle of a scene (see :mod:`~bt_meta.world.simulation.obstacles`); ``z`` ``None``: on the table."""

    name: str
    shape: str
    model: ObjectModel
    position: tuple[float, float, float | None]
    rpy: tuple[float, float, float]
    location: Location | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Variant:
    name: str
    description: str
    objects: tuple[SceneObject, ...]
    obstacles: tuple[SceneObstacle, ...] = ()
    """The scene's obstacles and the ones the variant adds."""


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    path: Path
    objects: tuple[SceneObject, ...]
    variants: dict[str, Variant]
    jitter_position: float = 0.0
    """Uniform noise (m) added to x and y of every object when built with a seed."""
    jitter_yaw: float = 0.0
    """Uniform noise (rad) added to yaw."""
    anchors: dict[str, tuple[tuple[float, float, float | None], tuple[float, float, float]]] = field(
        default_factory=dict
    )
    """Named frames on the table (position with ``z`` None = table top, rpy in radians), e.g. where a letter's
    origin cell is and which way its axes point."""
    obstacles: tuple[SceneObstacle, ...] = ()
    """Static obstacles of the nominal scene."""
    catalogues: tuple[Path, ...] = ()
    """The catalogue files (``catalogue:``) the scene's object types come from besides the built-in and shipped ones:
    a file written from this scene (a campaign's variant) names them too."""

    def obstacles_for(self, variant: str | None = None) -> tuple[SceneObstacle, ...]:
        """The nominal obstacles, or those of a named variant (the nominal ones plus what it adds)."""
        if variant is None or variant == "nominal":
            return self.obstacles
        self.objects_for(variant)  # an unknown variant is reported the same way
        return self.variants[variant].obstacles

    def anchor_transform(self, name: str, table_top_z: float) -> np.ndarray:
        """4x4 pose of a named anchor in the robot base frame."""
        if name not in self.anchors:
            known = ", ".join(self.anchors) or "none"
            raise ConfigError(f"scene {self.name!r} has no anchor {name!r}; anchors: {known}", self.path)
        (x, y, z), rpy = self.anchors[name]
        return pose_to_matrix((x, y, table_top_z if z is None else z, *rpy))

    @property
    def variant_names(self) -> tuple[str, ...]:
        return tuple(self.variants)

    def objects_for(self, variant: str | None = None) -> tuple[SceneObject, ...]:
        """The nominal objects, or those of a named variant."""
        if variant is None or variant == "nominal":
            return self.objects
        try:
            return self.variants[variant].objects
        except KeyError:
            known = ", ".join(self.variants) or "none"
            raise ConfigError(f"scene {self.name!r} has no variant {variant!r}; variants: {known}", self.path) from None

    def build(self, sim: Any, variant: str | None = None, *, seed: int | None = None, settle_steps: int = 120) -> None:
        """Spawn the (variant's) objects into a :class:`~bt_meta.world.simulation.sim.Simulation` and let them settle.

        With ``seed`` (default: the simulation's) and a ``jitter`` in the file, poses get seeded noise. An object
        off the table top raises :class:`ConfigError` at its line in the file.
        """
        objects = self.objects_for(variant)
        rng = np.random.default_rng(sim.seed if seed is None else seed)
        (x_lo, x_hi), (y_lo, y_hi) = sim.table.bounds
        dx, dy, dz = sim.robot.scene_offset  # scene frame -> robot base frame
        for obj in objects:
            x, y, z = obj.position
            x, y, z = x + dx, y + dy, None if z is None else z + dz
            roll, pitch, yaw = obj.rpy
            if self.jitter_position > 0.0 or self.jitter_yaw > 0.0:
                # Names of their own: the offset above must stay the same for every object.
                noise_x, noise_y = rng.uniform(-self.jitter_position, self.jitter_position, size=2)
                x, y = x + float(noise_x), y + float(noise_y)
                yaw += float(rng.uniform(-self.jitter_yaw, self.jitter_yaw))
            if not (x_lo <= x <= x_hi and y_lo <= y <= y_hi):
                message = (
                    f"object {obj.name!r} at ({x:.3f}, {y:.3f}) is off the table"
                    f" (x {x_lo:.3f}..{x_hi:.3f}, y {y_lo:.3f}..{y_hi:.3f})"
                )
                raise obj.location.error(message) if obj.location else ConfigError(message, self.path)
            pose = (x, y, 0.0 if z is None else z, roll, pitch, yaw)
            sim.spawn(obj.name, obj.model(), pose, on_table=z is None)
        for obstacle in self.obstacles_for(variant):
            x, y, z = obstacle.position
            z = sim.table.top_z if z is None else z + dz
            sim.add_obstacle(obstacle.name, obstacle.model, (x + dx, y + dy, z, *obstacle.rpy))
        if settle_steps:
            sim.step(settle_steps)


def scenes_dir() -> Path:
    return trees_dir() / "scenes"


def scene_names() -> list[str]:
    return sorted(p.stem for p in scenes_dir().glob("*.yaml"))


def load_scene(name: str | Path) -> Scene:
    """A scene by shipped name (``letters_A``) or by the path of a YAML file."""
    path = shipped_yaml_path(name, scenes_dir(), lambda shipped: f"no scene {str(name)!r}; shipped scenes: {shipped}",
                             "scene file not found")
    return _SceneFile(path).load()


# --------------------------------------------------------------------------------------------------------------
# Reading, with every node's position


class _SceneFile(YamlNodeReader):
    def at(self, node: yaml.Node) -> Location:
        return Location(str(self.path), node.start_mark.line + 1, node.start_mark.column + 1)

    def load(self) -> Scene:
        from bt_meta.safe_yaml import compose_yaml
        from bt_meta.user_files import read_user_text

        text = read_user_text(self.path, what="scene file", error=ConfigError)
        root = compose_yaml(text, str(self.path), ConfigError, syntax="not valid YAML")
        if root is None:
            raise ConfigError("the scene file is empty", self.path, 1, 1)
        top = self.mapping(root, "a scene file", _SCENE_KEYS)
        name = self.string(self.require(top, "scene", root, "a scene file"), "scene")
        extra: list[Path] = []
        if "catalogue" in top:
            for item in self.sequence(top["catalogue"][1], "catalogue"):
                extra.append(self.path.parent / self.string(item, "a catalogue file"))  # beside the scene file
                if not extra[-1].is_file():
                    raise self.error(f"catalogue file {extra[-1]} does not exist", item)
        self.types = object_types(extra)
        description = self.string(top["description"][1], "description") if "description" in top else ""
        objects_node = self.require(top, "objects", root, "a scene file")
        objects = self.object_list(objects_node, "objects", require_pose=True)
        if not objects:
            raise self.error("objects: a scene needs at least one object", objects_node)
        self.check_unique(objects, objects_node)
        jitter_position, jitter_yaw = 0.0, 0.0
        if "jitter" in top:
            jitter = self.mapping(top["jitter"][1], "jitter", _JITTER_KEYS)
            if "position" in jitter:
                jitter_position = self.number(jitter["position"][1], "jitter position (m)", minimum=0.0)
            if "yaw" in jitter:
                jitter_yaw = math.radians(self.number(jitter["yaw"][1], "jitter yaw (degrees)", minimum=0.0))
        obstacles: tuple[SceneObstacle, ...] = ()
        if "obstacles" in top:
            obstacles = self.obstacle_list(top["obstacles"][1], "obstacles")
            self.check_unique([*objects, *obstacles], top["obstacles"][1])
        variants: dict[str, Variant] = {}
        if "variants" in top:
            for key, (key_node, value) in self.mapping(top["variants"][1], "variants", None).items():
                if key == "nominal":
                    raise self.error("a variant cannot be called 'nominal' (that is the scene itself)", key_node)
                variants[key] = self.variant(key, value, objects, obstacles)
        anchors = {}
        if "anchors" in top:
            for key, (_, value) in self.mapping(top["anchors"][1], "anchors", None).items():
                anchors[key] = self.pose(value, key, what=f"anchor {key!r}")
        return Scene(name, description, self.path, objects, variants, jitter_position, jitter_yaw, anchors, obstacles,
                     tuple(path.resolve() for path in extra))

    # -- parts -----------------------------------------------------------------------------------------------

    def object_list(self, node: yaml.Node, what: str, *, require_pose: bool) -> tuple[SceneObject, ...]:
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(f"{what} must be a list of objects", node)
        return tuple(self.scene_object(item, f"{what}[{i}]", require_pose) for i, item in enumerate(node.value))

    def scene_object(self, node: yaml.Node, what: str, require_pose: bool) -> SceneObject:
        entries = self.mapping(node, what, _OBJECT_KEYS)
        name = self.string(self.require(entries, "name", node, what), f"{what} name")
        type_node = self.require(entries, "type", node, f"object {name!r}")
        type_name = self.string(type_node, f"object {name!r} type")
        if type_name not in self.types:
            raise self.error(
                f"object {name!r}: unknown type {type_name!r}; known: {', '.join(self.types)}", type_node
            )
        colour = self.colour(entries["colour"][1], name) if "colour" in entries else None
        if "pose" in entries:
            position, rpy = self.pose(entries["pose"][1], name)
        elif require_pose:
            raise self.error(f"object {name!r}: missing key 'pose'", node)
        else:
            position, rpy = (math.nan, math.nan, None), (0.0, 0.0, 0.0)  # inherited by replace
        return SceneObject(name, type_name, colour, position, rpy, self.at(node), self.types[type_name])

    def colour(self, node: yaml.Node, name: str) -> str:
        colour = self.string(node, f"object {name!r} colour")
        if colour not in COLOURS:
            raise self.error(f"object {name!r}: unknown colour {colour!r}; known: {', '.join(COLOURS)}", node)
        return colour

    def pose(
        self, node: yaml.Node, name: str, what: str | None = None
    ) -> tuple[tuple[float, float, float | None], tuple[float, float, float]]:
        what = what or f"object {name!r} pose"
        if not isinstance(node, yaml.SequenceNode) or len(node.value) != 6:
            got = f"{len(node.value)} values" if isinstance(node, yaml.SequenceNode) else "not a list"
            raise self.error(
                f"{what} must be [x, y, z, roll, pitch, yaw] (m, m, m or 'table', deg, deg, deg); got {got}", node
            )
        values: list[float | None] = []
        for i, item in enumerate(node.value):
            if i == 2 and isinstance(item, yaml.ScalarNode) and item.value == "table":
                values.append(None)
                continue
            values.append(self.number(item, f"{what}[{i}]" + (" (a number or 'table')" if i == 2 else "")))
        x, y, z, roll, pitch, yaw = values
        assert x is not None and y is not None and roll is not None and pitch is not None and yaw is not None
        return (x, y, z), (math.radians(roll), math.radians(pitch), math.radians(yaw))

    def obstacle_list(self, node: yaml.Node, what: str) -> tuple[SceneObstacle, ...]:
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(f"{what} must be a list of obstacles", node)
        return tuple(self.obstacle(item, f"{what}[{i}]") for i, item in enumerate(node.value))

    def obstacle(self, node: yaml.Node, what: str) -> SceneObstacle:
        entries = self.mapping(node, what, _OBSTACLE_KEYS)
        name = self.string(self.require(entries, "name", node, what), f"{what} name")
        shape_node = self.require(entries, "shape", node, f"obstacle {name!r}")
        shape = self.string(shape_node, f"obstacle {name!r} shape")
        if shape not in OBSTACLE_SHAPES:
            raise self.error(f"obstacle {name!r}: unknown shape {shape!r}; known: {', '.join(OBSTACLE_SHAPES)}",
                             shape_node)
        colour = self.colour(entries["colour"][1], name) if "colour" in entries else "grey"
        keys = set(OBSTACLE_SHAPES[shape])
        for key, (key_node, _) in entries.items():
            if key in {"size", "radius", "height", "thickness"} and key not in keys:
                raise self.error(f"obstacle {name!r}: a {shape} takes {', '.join(sorted(keys))}, not {key}", key_node)
        dimensions: dict[str, object] = {}
        for key in keys:
            if key not in entries:
                continue
            value_node = entries[key][1]
            if isinstance(value_node, yaml.SequenceNode):
                dimensions[key] = [self.number(v, f"obstacle {name!r} {key}") for v in value_node.value]
            else:
                dimensions[key] = self.number(value_node, f"obstacle {name!r} {key}")
        try:
            model = obstacle_model(shape, dimensions, colour)
        except ObstacleError as error:
            raise self.error(f"obstacle {name!r}: {error}", node) from None
        position, rpy = self.pose(self.require(entries, "pose", node, f"obstacle {name!r}"), name,
                                  what=f"obstacle {name!r} pose")
        return SceneObstacle(name, shape, model, position, rpy, self.at(node))

    def variant(self, name: str, node: yaml.Node, nominal: tuple[SceneObject, ...],
                nominal_obstacles: tuple[SceneObstacle, ...] = ()) -> Variant:
        entries = self.mapping(node, f"variant {name!r}", _VARIANT_KEYS)
        description = self.string(entries["description"][1], "description") if "description" in entries else ""
        if not any(k in entries for k in ("override", "remove", "replace", "add", "obstacles")):
            raise self.error(f"variant {name!r} changes nothing: give override, remove, replace, add or obstacles",
                             node)
        objects = list(nominal)

        def index(obj_name: str, at: yaml.Node) -> int:
            for i, obj in enumerate(objects):
                if obj.name == obj_name:
                    return i
            known = ", ".join(o.name for o in objects)
            raise self.error(f"variant {name!r}: no object {obj_name!r} to change; objects: {known}", at)

        if "override" in entries:
            for obj_name, (key_node, value) in self.mapping(entries["override"][1], "override", None).items():
                i = index(obj_name, key_node)
                changes = self.mapping(value, f"override of {obj_name!r}", _OVERRIDE_KEYS)
                obj = objects[i]
                if "type" in changes:
                    type_node = changes["type"][1]
                    type_name = self.string(type_node, "type")
                    if type_name not in self.types:
                        raise self.error(f"unknown type {type_name!r}; known: {', '.join(self.types)}", type_node)
                    obj = replace(obj, type=type_name, factory=self.types[type_name])
                if "colour" in changes:
                    obj = replace(obj, colour=self.colour(changes["colour"][1], obj_name))
                if "pose" in changes:
                    position, rpy = self.pose(changes["pose"][1], obj_name)
                    obj = replace(obj, position=position, rpy=rpy)
                objects[i] = replace(obj, location=self.at(value))
        if "remove" in entries:
            remove_node = entries["remove"][1]
            if not isinstance(remove_node, yaml.SequenceNode):
                raise self.error("remove must be a list of object names", remove_node)
            for item in remove_node.value:
                del objects[index(self.string(item, "an object name to remove"), item)]
        if "replace" in entries:
            for obj_name, (key_node, value) in self.mapping(entries["replace"][1], "replace", None).items():
                i = index(obj_name, key_node)
                old = objects[i]
                new = self.object_list(value, f"replacement of {obj_name!r}", require_pose=False)
                if not new:
                    raise self.error(f"replace {obj_name!r}: give at least one object (or use remove)", value)
                inherit = [math.isnan(o.position[0]) for o in new]
                if sum(inherit) > 1:
                    raise self.error(f"replace {obj_name!r}: only one replacement may omit its pose", value)
                new = tuple(
                    replace(o, position=old.position, rpy=old.rpy) if flag else o
                    for o, flag in zip(new, inherit, strict=True)
                )
                objects[i : i + 1] = list(new)
        if "add" in entries:
            objects += list(self.object_list(entries["add"][1], "add", require_pose=True))
        obstacles = list(nominal_obstacles)
        if "obstacles" in entries:
            obstacles += list(self.obstacle_list(entries["obstacles"][1], "obstacles"))
        self.check_unique([*objects, *obstacles], node)
        return Variant(name, description, tuple(objects), tuple(obstacles))

    def check_unique(self, objects: Sequence[SceneObject], node: yaml.Node) -> None:
        seen: dict[str, SceneObject] = {}
        for obj in objects:
            if obj.name in seen:
                first = seen[obj.name].location
                where = f" (first at line {first.line})" if first else ""
                if obj.location is not None:
                    raise obj.location.error(f"duplicate object name {obj.name!r}{where}")
                raise self.error(f"duplicate object name {obj.name!r}{where}", node)
            seen[obj.name] = obj

    # -- YAML node helpers -----------------------------------------------------------------------------------

    def number(self, node: yaml.Node, what: str, *, minimum: float | None = None) -> float:
        value = self.scalar(node, what)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(
                f"{what} must be a number, got {node.value!r}"
                if isinstance(node, yaml.ScalarNode)
                else f"{what} must be a number",
                node,
            )
        if minimum is not None and value < minimum:
            raise self.error(f"{what} must be at least {minimum}", node)
        return float(value)
