"""The perturbation spec of a campaign: a declarative YAML list of what may change in a generated variant.

A spec is a mapping with an optional ``family`` (checked against the family generated) and a list
``perturbations``; each item is a one-key mapping ``KIND: {parameters}``. Every perturbation applies to a variant
with its ``probability``, to one object drawn from ``objects``: ``all``, or a list whose items select by name
(``b0``), by type (``{type: megablok_1x1}``) or by role (``{role: grasped}``: the objects the task picks up;
``needed``: every object the problem names; ``active`` / ``reference``: the catalogue's magnet roles).
Kinds and their parameters (lengths in metres, angles in degrees; see docs/campaigns.md):

* ``shift`` -- ``distance: [lo, hi]``: move the object that far in a random direction on the table
* ``turn`` -- ``yaw: [lo, hi]``: turn it about the vertical
* ``rotate`` -- ``choices: [[roll, pitch, yaw], ...]``: lay it on a side / upside down (any axis)
* ``colour`` -- ``colours: [...]``: give it another colour (any the scene format accepts)
* ``replace_shape`` -- a 1x2 block becomes two 1x1 blocks, or two 1x1 blocks one 1x2
* ``remove`` -- ``spare_probability: p``: take it away; with probability ``p`` an object of the same type and
  colour lies elsewhere on the table
* ``distractor`` -- ``count: [lo, hi]``, ``types: [...]``, ``colours: [...]``, ``on_target_probability: p``:
  add objects the task does not name; with probability ``p`` one lies where the task puts something
* ``out_of_reach`` -- put the object somewhere on the table outside the arm's workspace
* ``obstacles`` -- ``count: [lo, hi]``, ``shapes: [...]`` (box, wall, post, shelf), ``size: [lo, hi]`` (the
  footprint's side, a wall's length, a post's diameter), ``height: [lo, hi]``, ``on_work_probability: p``,
  ``offset: [lo, hi]``: add static obstacles; with probability ``p`` the first stands ``offset`` from a place the
  task puts something or from the edge of an object drawn from ``objects`` (a shelf over it), else clear of both

Every mistake -- an unknown kind, parameter, object, colour or type -- is a :class:`SpecError` at
``path:line:column``.

Offers:

* :func:`load_spec` -- a :class:`Spec` from a file, checked against a scene's objects
* :func:`read_perturbations` -- the ``perturbations:`` list of another file (a campaign family file)
* :class:`Spec`, :class:`Perturbation`, :class:`SpecError`, :data:`KINDS`
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import ConfigError

__all__ = ["KINDS", "Perturbation", "Spec", "SpecError", "load_spec", "read_perturbations"]


class SpecError(ConfigError):
    """A perturbation spec that is wrong, located at ``path:line:column``."""


#: kind -> {parameter: (type, default)}; ``probability`` and ``objects`` are common to every kind.
KINDS: dict[str, dict[str, tuple[str, Any]]] = {
    "shift": {"distance": ("range", (0.01, 0.05))},
    "turn": {"yaw": ("range", (-45.0, 45.0))},
    "rotate": {"choices": ("rotations", ((90.0, 0.0, 0.0), (180.0, 0.0, 0.0)))},
    "colour": {"colours": ("colours", ("red", "green", "yellow"))},
    "replace_shape": {},
    "remove": {"spare_probability": ("probability", 0.5)},
    "distractor": {"count": ("count", (1, 2)), "types": ("types", ("megablok_1x1",)),
                   "colours": ("colours", ("green",)), "on_target_probability": ("probability", 0.0)},
    "out_of_reach": {},
    "obstacles": {"count": ("count", (1, 1)), "shapes": ("shapes", ("box", "wall", "post", "shelf")),
                  "size": ("length", (0.04, 0.12)), "height": ("length", (0.05, 0.20)),
                  "on_work_probability": ("probability", 0.5), "offset": ("range", (0.0, 0.05))},
}
_COMMON = {"probability", "objects"}


@dataclass(frozen=True)
class Perturbation:
    kind: str
    probability: float
    objects: tuple[str, ...] | None
    """Object names to draw from; ``None``: every object of the scene."""
    params: dict[str, Any] = field(default_factory=dict)
    line: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {self.kind: {"probability": self.probability, "objects": "all" if self.objects is None
                            else list(self.objects), **{k: _plain(v) for k, v in self.params.items()}}}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


@dataclass(frozen=True)
class Spec:
    path: str
    family: str | None
    perturbations: tuple[Perturbation, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"family": self.family, "perturbations": [p.to_dict() for p in self.perturbations]}


def load_spec(path: str | Path, objects: Sequence[str] | Mapping[str, tuple[str, str | None]], *,
              family: str | None = None, roles: Mapping[str, Sequence[str]] | None = None) -> Spec:
    """Read a spec; its objects must be among ``objects`` (names, or name -> (type, catalogue role)), its roles
    among ``roles`` (role -> object names) and its ``family`` (if given) be ``family``."""
    path = Path(path)
    if not path.is_file():
        raise SpecError("spec file not found", path)
    return _SpecReader(path, objects, family, roles).read()


def read_perturbations(path: str | Path, node: yaml.Node, objects: Sequence[str] | Mapping[str, tuple[str, str | None]],
                       *, family: str | None = None, roles: Mapping[str, Sequence[str]] | None = None) -> Spec:
    """The ``perturbations:`` list ``node`` of the file ``path`` (a campaign family file) as a :class:`Spec`."""
    reader = _SpecReader(Path(path), objects, family, roles)
    return Spec(str(path), family, reader.perturbations(node))


class _SpecReader:
    def __init__(self, path: Path, objects: Sequence[str] | Mapping[str, tuple[str, str | None]],
                 family: str | None, roles: Mapping[str, Sequence[str]] | None = None) -> None:
        self.path = path
        self.objects_info = dict(objects) if isinstance(objects, Mapping) else {n: ("", None) for n in objects}
        self.object_names = tuple(self.objects_info)
        self.family = family
        self.roles = {role: tuple(names) for role, names in (roles or {}).items()}
        for name, (_, role) in self.objects_info.items():
            if role:
                self.roles.setdefault(role, ())
                self.roles[role] = (*self.roles[role], name)

    def error(self, message: str, node: yaml.Node | None) -> SpecError:
        if node is None:
            return SpecError(message, self.path)
        return SpecError(message, self.path, node.start_mark.line + 1, node.start_mark.column + 1)

    def read(self) -> Spec:
        try:
            root = yaml.compose(self.path.read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
        except yaml.MarkedYAMLError as error:
            mark = error.problem_mark or error.context_mark
            raise SpecError(f"not valid YAML: {error.problem or error}", self.path,
                            mark.line + 1 if mark else None, mark.column + 1 if mark else None) from None
        if root is None:
            raise SpecError("the spec is empty: give `perturbations:`", self.path, 1, 1)
        top = self.mapping(root, "a spec", {"family", "perturbations", "description"})
        family = None
        if "family" in top:
            _, node = top["family"]
            family = self.string(node, "family")
            if self.family is not None and family != self.family:
                raise self.error(f"this spec is for family {family!r}, not {self.family!r}", node)
        if "perturbations" not in top:
            raise self.error("a spec needs `perturbations:` (a list)", root)
        return Spec(str(self.path), family, self.perturbations(top["perturbations"][1]))

    def perturbations(self, items: yaml.Node) -> tuple[Perturbation, ...]:
        if not isinstance(items, yaml.SequenceNode) or not items.value:
            raise self.error("perturbations must be a non-empty list of `KIND: {parameters}`", items)
        return tuple(self.perturbation(item) for item in items.value)

    def perturbation(self, node: yaml.Node) -> Perturbation:
        if not isinstance(node, yaml.MappingNode) or len(node.value) != 1:
            raise self.error(f"a perturbation is one `KIND: {{parameters}}`; kinds: {', '.join(KINDS)}", node)
        key_node, value = node.value[0]
        kind = str(key_node.value)
        if kind not in KINDS:
            raise self.error(f"unknown perturbation {kind!r}; known: {', '.join(KINDS)}", key_node)
        schema = KINDS[kind]
        if isinstance(value, yaml.ScalarNode) and value.value in ("", "null", "~"):
            entries: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        else:
            entries = self.mapping(value, f"perturbation {kind!r}", _COMMON | set(schema))
        probability = 1.0
        if "probability" in entries:
            probability = self.probability(entries["probability"][1], "probability")
        objects = None
        if "objects" in entries:
            objects = self.objects(entries["objects"][1])
        params = {}
        for name, (kind_of, default) in schema.items():
            params[name] = self.parameter(entries[name][1], kind_of, name) if name in entries else default
        return Perturbation(kind, probability, objects, params, key_node.start_mark.line + 1)

    # -- parameters ------------------------------------------------------------------------------------------

    def parameter(self, node: yaml.Node, kind_of: str, name: str) -> Any:
        if kind_of == "probability":
            return self.probability(node, name)
        if kind_of == "range":
            values = self.numbers(node, name, 2)
            if values[0] > values[1]:
                raise self.error(f"{name}: [lo, hi] with lo <= hi", node)
            return tuple(values)
        if kind_of == "length":
            values = self.numbers(node, name, 2)
            if not 0.0 < values[0] <= values[1]:
                raise self.error(f"{name}: [lo, hi] metres with 0 < lo <= hi", node)
            return tuple(values)
        if kind_of == "count":
            values = self.numbers(node, name, 2)
            if not all(float(v).is_integer() and v >= 0 for v in values) or values[0] > values[1]:
                raise self.error(f"{name}: [lo, hi], whole numbers, 0 <= lo <= hi", node)
            return int(values[0]), int(values[1])
        if kind_of == "rotations":
            if not isinstance(node, yaml.SequenceNode) or not node.value:
                raise self.error(f"{name}: a non-empty list of [roll, pitch, yaw] (degrees)", node)
            return tuple(tuple(self.numbers(item, f"{name} entry", 3)) for item in node.value)
        if kind_of == "colours":
            from bt_meta.world.simulation.objects import COLOURS

            return self.names(node, name, COLOURS, "colour")
        if kind_of == "shapes":
            from bt_meta.world.simulation.obstacles import OBSTACLE_SHAPES

            return self.names(node, name, OBSTACLE_SHAPES, "obstacle shape")
        if kind_of == "types":
            from bt_meta.world.simulation.objects import OBJECT_TYPES

            return self.names(node, name, OBJECT_TYPES, "object type")
        raise AssertionError(kind_of)  # pragma: no cover - KINDS names only the kinds above

    def probability(self, node: yaml.Node, what: str) -> float:
        value = self.number(node, what)
        if not 0.0 <= value <= 1.0:
            raise self.error(f"{what} must be between 0 and 1, got {value}", node)
        return value

    def objects(self, node: yaml.Node) -> tuple[str, ...] | None:
        if isinstance(node, yaml.ScalarNode) and node.value == "all":
            return None
        if not isinstance(node, yaml.SequenceNode) or not node.value:
            raise self.error("objects: `all` or a non-empty list of object names, {type: T} or {role: R}", node)
        out: list[str] = []
        for item in node.value:
            for name in self.selected(item):
                if name not in out:
                    out.append(name)
        return tuple(out)

    def selected(self, item: yaml.Node) -> list[str]:
        """The scene objects one ``objects:`` item selects: a name, ``{type: T}`` or ``{role: R}``."""
        if isinstance(item, yaml.MappingNode):
            entries = self.mapping(item, "an object selector", {"type", "role"})
            if len(entries) != 1:
                raise self.error("an object selector is {type: T} or {role: R}", item)
            (key, (_, value)), = entries.items()
            wanted = self.string(value, key)
            if key == "type":
                names = [n for n, (t, _) in self.objects_info.items() if t == wanted]
                known = sorted({t for t, _ in self.objects_info.values() if t})
            else:
                names = [n for n in self.roles.get(wanted, ()) if n in self.objects_info]
                known = sorted(self.roles)
            if wanted not in known:
                raise self.error(f"no object of {key} {wanted!r} in the scene; {key}s: {', '.join(known) or 'none'}",
                                 value)
            if not names:
                raise self.error(f"no object of {key} {wanted!r} in the scene", value)
            return names
        name = self.string(item, "an object name")
        if name not in self.object_names:
            raise self.error(f"unknown object {name!r}; the scene's objects: {', '.join(self.object_names)}", item)
        return [name]

    def names(self, node: yaml.Node, what: str, known: Any, noun: str) -> tuple[str, ...]:
        if not isinstance(node, yaml.SequenceNode) or not node.value:
            raise self.error(f"{what}: a non-empty list of {noun} names", node)
        out = []
        for item in node.value:
            name = self.string(item, f"a {noun}")
            if name not in known:
                raise self.error(f"unknown {noun} {name!r}; known: {', '.join(known)}", item)
            out.append(name)
        return tuple(out)

    def numbers(self, node: yaml.Node, what: str, count: int) -> list[float]:
        if not isinstance(node, yaml.SequenceNode) or len(node.value) != count:
            raise self.error(f"{what}: a list of {count} numbers", node)
        return [self.number(item, what) for item in node.value]

    def number(self, node: yaml.Node, what: str) -> float:
        value = yaml.safe_load(node.value) if isinstance(node, yaml.ScalarNode) else None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(f"{what} must be a number", node)
        return float(value)

    def string(self, node: yaml.Node, what: str) -> str:
        if not isinstance(node, yaml.ScalarNode) or not node.value:
            raise self.error(f"{what} must be a name", node)
        return str(node.value)

    def mapping(self, node: yaml.Node, what: str, allowed: set[str]) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self.error(f"{what} must be a mapping", node)
        out: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key, value in node.value:
            name = str(key.value)
            if name in out:
                raise self.error(f"{what}: duplicate key {name!r}", key)
            if name not in allowed:
                raise self.error(f"{what}: unknown key {name!r}; expected one of {', '.join(sorted(allowed))}", key)
            out[name] = (key, value)
        return out
