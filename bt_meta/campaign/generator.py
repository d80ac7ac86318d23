"""``campaign generate``: draw variants of a family's scene from a perturbation spec and a seed.

Variant ``k`` of seed ``s`` draws from ``numpy.random.default_rng([s, k])``: the same seed and spec give the same
files, and variant ``k`` does not depend on how many others are drawn. Each perturbation of the spec applies with
its probability to one object drawn from its ``objects``; a draw that changes nothing is drawn again. New
positions (spares, distractors, shifts) are rejection-sampled on free table space, clear of the other objects and
of the places the task puts things (unless a distractor is meant to block one). Obstacles (``obstacles``) never
overlap an object's footprint (a shelf may stand over one that fits under its board); whether one is in the way
is not decided here but by the labeller, on the true scene.

Each variant is written as an ordinary scene file (``variants/<name>.yaml``): the nominal objects plus one variant
``perturbed`` made of ``override`` / ``remove`` / ``add`` / ``obstacles``, so ``bt-meta run`` and the scene loader
read it as any shipped scene. Its expected outcome comes from :mod:`bt_meta.campaign.labeller`, for the campaign's
robot. Generation writes into a temporary folder renamed when complete: a failure leaves no half-written one.

Offers:

* :func:`draw_variant` -- the objects and the list of changes of variant ``k`` (pure; no simulator)
* :func:`scene_text` -- the scene file of a variant
* :func:`generate` -- write ``n`` variants, label them, write the manifest
* :class:`Placed` -- one object of a variant (name, type, colour, position, rpy in degrees)
* :class:`Obstacle` -- one static obstacle a variant adds (shape, dimensions, footprint centre, yaw)
* :data:`VARIANT_NAME` -- the variant's name inside its scene file
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bt_meta.campaign.spec import Perturbation, Spec

__all__ = ["VARIANT_NAME", "Obstacle", "Placed", "draw_variant", "generate", "scene_text"]

VARIANT_NAME = "perturbed"

#: Where spares and distractors are put down: the part of the table the right arm reaches pointing down
#: (bt_meta.world.simulation.sim.Table's docstring: x 0.45..0.75, y -0.55..0.15), kept off the table's edge.
FREE_REGION = ((0.47, 0.74), (-0.55, 0.12))
#: Outside the arm's workspace but on the table (x up to 1.05): where ``out_of_reach`` puts an object.
FAR_REGION = ((0.90, 1.02), (-0.60, 0.40))
CLEARANCE = 0.012
"""Gap (m) kept between the footprints of sampled objects."""
TARGET_CLEARANCE = 0.09
"""Distance (m) sampled objects keep from the places the task puts things."""
_TRIES = 40
_MAX_DRAWS = 25


@dataclass(frozen=True)
class Placed:
    name: str
    type: str
    colour: str | None
    x: float
    y: float
    z: float | None
    """``None``: resting on the table."""
    rpy: tuple[float, float, float]
    """Degrees, as scene files write them."""

    def pose(self) -> list[Any]:
        return [round(self.x, 4), round(self.y, 4), "table" if self.z is None else round(self.z, 4),
                *(round(v, 2) for v in self.rpy)]


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle of a variant: its footprint centre on the table, its yaw (degrees) and dimensions (m)."""

    name: str
    shape: str
    dimensions: dict[str, Any]
    x: float
    y: float
    yaw: float

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "shape": self.shape, **self.dimensions,
                "pose": [round(self.x, 4), round(self.y, 4), "table", 0, 0, round(self.yaw, 2)]}

    def walls(self) -> list[tuple[float, float, float, float]]:
        """The footprint's standing parts as rectangles (centre x, centre y, half x, half y) in the obstacle's
        frame; a post is one square of its diameter; a shelf's top board is not a standing part."""
        if self.shape == "post":
            r = float(self.dimensions["radius"])
            return [(0.0, 0.0, r, r)]
        sx, sy, _ = self.dimensions["size"]
        if self.shape == "shelf":
            t = float(self.dimensions.get("thickness", 0.02))
            return [(0.0, -(sy - t) / 2.0, sx / 2.0, t / 2.0), (0.0, (sy - t) / 2.0, sx / 2.0, t / 2.0)]
        return [(0.0, 0.0, sx / 2.0, sy / 2.0)]

    def bounding_radius(self) -> float:
        if self.shape == "post":
            return float(self.dimensions["radius"])
        sx, sy, _ = self.dimensions["size"]
        return 0.5 * math.hypot(sx, sy)

    def distance(self, x: float, y: float) -> float:
        """Distance (m) from a point on the table to the nearest standing part of the footprint."""
        yaw = math.radians(self.yaw)
        c, s = math.cos(yaw), math.sin(yaw)
        u, v = c * (x - self.x) + s * (y - self.y), -s * (x - self.x) + c * (y - self.y)
        best = math.inf
        for cx, cy, hx, hy in self.walls():
            dx, dy = max(abs(u - cx) - hx, 0.0), max(abs(v - cy) - hy, 0.0)
            best = min(best, math.hypot(dx, dy))
        return best


_TYPES: ContextVar[dict[str, Callable[[str | None], Any]] | None] = ContextVar("campaign_object_types", default=None)
"""The object types of the scene being perturbed (built-in, shipped catalogue and the scene's ``catalogue:``)."""


def make_model(type_name: str) -> Any:
    """The model of an object type as the scene being perturbed defines it: a user's catalogue types too."""
    from bt_meta.world.simulation.objects import make_model as built_in

    types = _TYPES.get()
    if types is not None and type_name in types:
        return types[type_name](None)
    return built_in(type_name)


def _radius(type_name: str) -> float:
    """Half the diagonal of an object's footprint (any yaw)."""
    low, high = make_model(type_name).extent()
    return 0.5 * float(math.hypot(high[0] - low[0], high[1] - low[1]))


class _Draw:
    """One variant's objects while perturbations apply to them."""

    def __init__(self, objects: Sequence[Placed], targets: Sequence[tuple[float, float]], rng: np.random.Generator,
                 table: tuple[tuple[float, float], tuple[float, float]]) -> None:
        self.objects = list(objects)
        self.targets = list(targets)
        self.rng = rng
        self.table = table
        self.changes: list[dict[str, Any]] = []
        self.obstacles: list[Obstacle] = []
        self._names = {o.name for o in objects}

    def index(self, name: str) -> int | None:
        return next((i for i, o in enumerate(self.objects) if o.name == name), None)

    def fresh_name(self, base: str) -> str:
        name, k = base, 2
        while name in self._names:
            name, k = f"{base}_{k}", k + 1
        self._names.add(name)
        return name

    def free(self, x: float, y: float, type_name: str, ignore: Sequence[str] = (), *, near_targets: bool = False
             ) -> bool:
        (x_lo, x_hi), (y_lo, y_hi) = self.table
        r = _radius(type_name)
        if not (x_lo + r <= x <= x_hi - r and y_lo + r <= y <= y_hi - r):
            return False
        for other in self.objects:
            if other.name in ignore or other.z is not None:
                continue
            if math.hypot(other.x - x, other.y - y) < r + _radius(other.type) + CLEARANCE:
                return False
        if any(o.distance(x, y) < r + CLEARANCE for o in self.obstacles):
            return False
        return near_targets or all(math.hypot(tx - x, ty - y) >= TARGET_CLEARANCE for tx, ty in self.targets)

    def sample_free(self, type_name: str, region: tuple[tuple[float, float], tuple[float, float]],
                    ignore: Sequence[str] = ()) -> tuple[float, float] | None:
        (x_lo, x_hi), (y_lo, y_hi) = region
        for _ in range(_TRIES):
            x, y = float(self.rng.uniform(x_lo, x_hi)), float(self.rng.uniform(y_lo, y_hi))
            if self.free(x, y, type_name, ignore):
                return x, y
        return None


def _choose_target(draw: _Draw, p: Perturbation, nominal: Sequence[str]) -> Placed | None:
    pool = [name for name in (p.objects or nominal) if draw.index(name) is not None]
    if not pool:
        return None
    return draw.objects[draw.index(str(draw.rng.choice(pool)))]  # type: ignore[index]


def _shift(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    lo, hi = p.params["distance"]
    for _ in range(_TRIES):
        distance, angle = float(draw.rng.uniform(lo, hi)), float(draw.rng.uniform(0.0, 2.0 * math.pi))
        x, y = obj.x + distance * math.cos(angle), obj.y + distance * math.sin(angle)
        if draw.free(x, y, obj.type, ignore=[obj.name], near_targets=True):
            draw.objects[draw.index(obj.name)] = replace(obj, x=x, y=y)  # type: ignore[index]
            return {"kind": "shift", "object": obj.name, "distance": round(distance, 4)}
    return None


def _turn(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    lo, hi = p.params["yaw"]
    angle = float(draw.rng.uniform(lo, hi))
    roll, pitch, yaw = obj.rpy
    draw.objects[draw.index(obj.name)] = replace(obj, rpy=(roll, pitch, yaw + angle))  # type: ignore[index]
    return {"kind": "turn", "object": obj.name, "yaw": round(angle, 2)}


def _rotate(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    choices = p.params["choices"]
    roll, pitch, yaw = choices[int(draw.rng.integers(len(choices)))]
    draw.objects[draw.index(obj.name)] = replace(  # type: ignore[index]
        obj, z=None, rpy=(float(roll), float(pitch), obj.rpy[2] + float(yaw)))
    return {"kind": "rotate", "object": obj.name, "rpy": [roll, pitch, yaw]}


def _colour(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    others = [c for c in p.params["colours"] if c != obj.colour]
    if not others:
        return None
    colour = str(draw.rng.choice(others))
    draw.objects[draw.index(obj.name)] = replace(obj, colour=colour)  # type: ignore[index]
    return {"kind": "colour", "object": obj.name, "colour": colour}


def _replace_shape(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    from bt_meta.world.simulation.objects import LB

    i = draw.index(obj.name)
    assert i is not None
    if obj.type == "megablok_1x2":
        yaw = math.radians(obj.rpy[2])
        ax, ay = math.cos(yaw), math.sin(yaw)
        first = replace(obj, type="megablok_1x1", x=obj.x - 0.5 * LB * ax - 0.004 * ax,
                        y=obj.y - 0.5 * LB * ay - 0.004 * ay)
        second = replace(obj, name=draw.fresh_name(f"{obj.name}_b"), type="megablok_1x1",
                         x=obj.x + 0.5 * LB * ax + 0.004 * ax, y=obj.y + 0.5 * LB * ay + 0.004 * ay)
        draw.objects[i:i + 1] = [first, second]
        return {"kind": "replace_shape", "object": obj.name, "into": [first.name, second.name]}
    if obj.type == "megablok_1x1":
        partners = [o for o in draw.objects if o.type == "megablok_1x1" and o.name != obj.name and o.z is None]
        if not partners:
            return None
        partner = partners[int(draw.rng.integers(len(partners)))]
        block = replace(obj, type="megablok_1x2")
        gone = [obj.name, partner.name]
        spot = (block.x, block.y) if draw.free(block.x, block.y, block.type, ignore=gone,
                                                near_targets=True) else draw.sample_free(block.type, FREE_REGION,
                                                                                          ignore=gone)
        if spot is None:
            return None  # nothing changed: the partner stays (a variant must hold what its changes say)
        del draw.objects[draw.index(partner.name)]  # type: ignore[arg-type]
        i = draw.index(obj.name)
        assert i is not None
        draw.objects[i] = replace(block, x=spot[0], y=spot[1])
        return {"kind": "replace_shape", "objects": [obj.name, partner.name], "into": [obj.name]}
    return None


def _remove(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    del draw.objects[draw.index(obj.name)]  # type: ignore[arg-type]
    change: dict[str, Any] = {"kind": "remove", "object": obj.name, "spare": None}
    if draw.rng.random() < p.params["spare_probability"]:
        spot = draw.sample_free(obj.type, FREE_REGION)
        if spot is not None:
            spare = Placed(draw.fresh_name(f"spare_{obj.name}"), obj.type, obj.colour, spot[0], spot[1], None,
                           (0.0, 0.0, float(draw.rng.uniform(-30.0, 30.0))))
            draw.objects.append(spare)
            change["spare"] = spare.name
    return change


def _distractor(draw: _Draw, p: Perturbation, obj: Placed | None) -> dict[str, Any] | None:
    lo, hi = p.params["count"]
    count = int(draw.rng.integers(lo, hi + 1))
    added, blocking = [], None
    for k in range(count):
        type_name = str(draw.rng.choice(p.params["types"]))
        colour = str(draw.rng.choice(p.params["colours"]))
        spot = None
        z = None
        if k == 0 and draw.targets and draw.rng.random() < p.params["on_target_probability"]:
            tx, ty = draw.targets[int(draw.rng.integers(len(draw.targets)))]
            spot, blocking = (tx, ty), [round(tx, 4), round(ty, 4)]
            z = _resting_on(draw, type_name, tx, ty)
        else:
            spot = draw.sample_free(type_name, FREE_REGION)
        if spot is None:
            continue
        item = Placed(draw.fresh_name("distractor"), type_name, colour, spot[0], spot[1], z,
                      (0.0, 0.0, float(draw.rng.uniform(-45.0, 45.0))))
        draw.objects.append(item)
        added.append(item.name)
    if not added:
        return None
    return {"kind": "distractor", "objects": added, "blocking": blocking}


def _resting_on(draw: _Draw, type_name: str, x: float, y: float) -> float | None:
    """The height (scene frame) at which an object of ``type_name`` rests on the object on the table under (x, y) --
    a target on a part (the reference's magnet, the housing's bore) -- or ``None`` (on the table) when nothing is
    there. Put on the table at the part's place instead, the two would start inside each other and the simulator
    would throw the part over as it settles."""
    from bt_meta.world.simulation.objects import rpy_to_matrix
    from bt_meta.world.simulation.sim import Table

    for other in draw.objects:
        if other.z is not None or math.hypot(other.x - x, other.y - y) >= _radius(other.type):
            continue
        roll, pitch = (math.radians(v) for v in other.rpy[:2])
        heights = (make_model(other.type).points() @ rpy_to_matrix(roll, pitch, 0.0).T)[:, 2]
        top = Table().top_z + float(heights.max() - heights.min())
        return top + make_model(type_name).lowest_z(0.0, 0.0) + 0.002
    return None


def _out_of_reach(draw: _Draw, p: Perturbation, obj: Placed) -> dict[str, Any] | None:
    spot = draw.sample_free(obj.type, FAR_REGION, ignore=[obj.name])
    if spot is None:
        return None
    draw.objects[draw.index(obj.name)] = replace(obj, x=spot[0], y=spot[1])  # type: ignore[index]
    return {"kind": "out_of_reach", "object": obj.name, "position": [round(spot[0], 4), round(spot[1], 4)]}


def _obstacle_shape(draw: _Draw, p: Perturbation, shape: str, under: tuple[float, float]) -> dict[str, Any]:
    """Dimensions of an obstacle of ``shape`` drawn from the spec's ranges; a shelf leaves room under its board
    for an object of ``under`` = (footprint radius, height)."""
    lo, hi = p.params["size"]
    h_lo, h_hi = p.params["height"]
    size = [float(draw.rng.uniform(lo, hi)) for _ in range(2)]
    height = float(draw.rng.uniform(h_lo, h_hi))
    if shape == "post":
        return {"radius": size[0] / 2.0, "height": height}
    if shape == "wall":
        return {"size": [size[0] * 2.0, 0.02, height]}
    if shape == "shelf":
        thickness = 0.02
        radius, tall = under
        inner = max(size[1], 2.0 * (radius + CLEARANCE) + 0.01)
        return {"size": [size[0], inner + 2.0 * thickness, max(height, tall + 0.03 + thickness)],
                "thickness": thickness}
    return {"size": [size[0], size[1], height]}


def _obstacles(draw: _Draw, p: Perturbation, obj: Placed | None) -> dict[str, Any] | None:
    """Static obstacles: the first, with ``on_work_probability``, within ``offset`` of a place the task puts
    something or of ``obj`` (a shelf centred over it); the others (and a first that is not) on free table space."""

    lo, hi = p.params["count"]
    count = int(draw.rng.integers(lo, hi + 1))
    (x_lo, x_hi), (y_lo, y_hi) = draw.table
    added, near = [], None
    for k in range(count):
        shape = str(draw.rng.choice(p.params["shapes"]))
        work = None
        if k == 0 and draw.rng.random() < p.params["on_work_probability"]:
            points = [(tx, ty, f"target ({tx:.3f}, {ty:.3f})") for tx, ty in draw.targets]
            if obj is not None:
                points.append((obj.x, obj.y, f"object {obj.name}"))
            if points:
                work = points[int(draw.rng.integers(len(points)))]
        under = (0.03, 0.04)
        if work is not None and work[2].startswith("object") and obj is not None:
            low, high = make_model(obj.type).extent()
            under = (_radius(obj.type), float(max(high - low)))
        dimensions = _obstacle_shape(draw, p, shape, under)
        beside = 0.0  # an obstacle near an object stands beside its footprint (offset from its edge), not in it
        if work is not None:
            beside = max((_radius(o.type) + CLEARANCE for o in draw.objects
                          if math.hypot(o.x - work[0], o.y - work[1]) < _radius(o.type)), default=0.0)
        placed = None
        for _ in range(_TRIES):
            yaw = float(draw.rng.uniform(-90.0, 90.0))
            if work is not None:
                off_lo, off_hi = p.params["offset"]
                distance = 0.0 if shape == "shelf" else (beside + _half_width(shape, dimensions)
                                                          + float(draw.rng.uniform(off_lo, off_hi)))
                angle = float(draw.rng.uniform(0.0, 2.0 * math.pi))
                x, y = work[0] + distance * math.cos(angle), work[1] + distance * math.sin(angle)
            else:
                x, y = float(draw.rng.uniform(x_lo, x_hi)), float(draw.rng.uniform(y_lo, y_hi))
            candidate = Obstacle(draw.fresh_name("obstacle"), shape, dimensions, x, y, yaw)
            if _obstacle_fits(draw, candidate, clear=work is None):
                placed = candidate
                break
        if placed is None:
            continue
        draw.obstacles.append(placed)
        added.append(placed.name)
        if work is not None:
            near = work[2]
    if not added:
        return None
    return {"kind": "obstacles", "obstacles": [o.to_dict() for o in draw.obstacles if o.name in added],
            "near": near}


def _half_width(shape: str, dimensions: dict[str, Any]) -> float:
    """Half the narrowest side of an obstacle's footprint (a post's radius)."""
    if shape == "post":
        return float(dimensions["radius"])
    return 0.5 * float(min(dimensions["size"][:2]))


def _obstacle_fits(draw: _Draw, obstacle: Obstacle, *, clear: bool) -> bool:
    """On the table, off every object's footprint and every other obstacle; ``clear``: also away from the places
    the task puts things."""
    (x_lo, x_hi), (y_lo, y_hi) = draw.table
    r = obstacle.bounding_radius()
    if not (x_lo + r <= obstacle.x <= x_hi - r and y_lo + r <= obstacle.y <= y_hi - r):
        return False
    for other in draw.objects:
        if obstacle.distance(other.x, other.y) < _radius(other.type) + CLEARANCE:
            return False
    for other in draw.obstacles:
        if math.hypot(other.x - obstacle.x, other.y - obstacle.y) < r + other.bounding_radius() + CLEARANCE:
            return False
    return not clear or all(obstacle.distance(tx, ty) >= TARGET_CLEARANCE for tx, ty in draw.targets)


_APPLY: dict[str, Callable[[_Draw, Perturbation, Any], dict[str, Any] | None]] = {
    "shift": _shift, "turn": _turn, "rotate": _rotate, "colour": _colour, "replace_shape": _replace_shape,
    "remove": _remove, "distractor": _distractor, "out_of_reach": _out_of_reach, "obstacles": _obstacles,
}


def draw_variant(nominal: Sequence[Placed], spec: Spec, seed: int, index: int, *,
                 targets: Sequence[tuple[float, float]] = (),
                 table: tuple[tuple[float, float], tuple[float, float]] = ((0.45, 1.05), (-0.65, 0.45)),
                 ) -> tuple[list[Placed], list[dict[str, Any]]]:
    """Variant ``index``: (objects, changes). At least one change; deterministic in (seed, index, spec)."""
    rng = np.random.default_rng([seed, index])
    names = [o.name for o in nominal]
    for _ in range(_MAX_DRAWS):
        draw = _Draw(nominal, targets, rng, table)
        for p in spec.perturbations:
            if rng.random() >= p.probability:
                continue
            obj = None if p.kind == "distractor" else _choose_target(draw, p, names)
            if obj is None and p.kind not in ("distractor", "obstacles"):
                continue
            change = _APPLY[p.kind](draw, p, obj)
            if change is not None:
                draw.changes.append(change)
        if draw.changes:
            return draw.objects, draw.changes
    raise ValueError(f"the spec changed nothing in {_MAX_DRAWS} draws: raise some probability")


def placed_objects(scene: Any) -> list[Placed]:
    """A loaded scene's nominal objects as :class:`Placed` (degrees)."""
    out = []
    for obj in scene.objects:
        x, y, z = obj.position
        out.append(Placed(obj.name, obj.type, obj.colour, x, y, z, tuple(math.degrees(v) for v in obj.rpy)))
    return out


def _flow(obj: Placed) -> str:
    colour = f", colour: {obj.colour}" if obj.colour else ""
    pose = ", ".join(str(v) for v in obj.pose())
    return f"{{name: {obj.name}, type: {obj.type}{colour}, pose: [{pose}]}}"


def scene_text(scene: Any, name: str, objects: Sequence[Placed], changes: Sequence[dict[str, Any]],
               expected: str | None = None, reason: str = "") -> str:
    """A scene file: the nominal scene's objects and anchors, and variant :data:`VARIANT_NAME` giving
    ``objects``."""
    nominal = {o.name: o for o in placed_objects(scene)}
    final = {o.name: o for o in objects}
    lines = [f"# Generated by `bt-meta campaign generate` from scene {scene.name!r}.",
             f"# Changes: {'; '.join(_change_text(c) for c in changes)}"]
    if expected:
        lines.append(f"# Expected outcome (from ground truth): {expected} -- {reason}")
    lines += [f"scene: {name}", f"description: {scene.name} perturbed ({len(changes)} change(s))"]
    if scene.catalogues:  # the scene's own object types, wherever the variant file is read
        lines.append(f"catalogue: [{', '.join(json.dumps(str(path)) for path in scene.catalogues)}]")
    if scene.obstacles:  # the nominal scene's obstacles (a tray the task places on), as its file writes them
        lines.append("obstacles:")
        lines += [f"  - {json.dumps(entry)}" for entry in _nominal_obstacles(scene)]
    if scene.anchors:
        lines.append("anchors:")
        for anchor, ((x, y, z), rpy) in scene.anchors.items():
            values = [x, y, "table" if z is None else z, *(round(math.degrees(v), 4) for v in rpy)]
            lines.append(f"  {anchor}: [{', '.join(str(v) for v in values)}]")
    lines.append("objects:")
    lines += [f"  - {_flow(o)}" for o in nominal.values()]
    description = json.dumps("; ".join(_change_text(c) for c in changes))
    lines += ["variants:", f"  {VARIANT_NAME}:", f"    description: {description}"]
    removed = [n for n in nominal if n not in final or final[n].type != nominal[n].type]
    overrides = {n: final[n] for n in nominal if n in final and final[n] != nominal[n] and n not in removed}
    added = [o for n, o in final.items() if n not in nominal or n in removed]
    if overrides:
        lines.append("    override:")
        for n, o in overrides.items():
            colour = f", colour: {o.colour}" if o.colour and o.colour != nominal[n].colour else ""
            lines.append(f"      {n}: {{pose: [{', '.join(str(v) for v in o.pose())}]{colour}}}")
    if removed:
        lines.append(f"    remove: [{', '.join(removed)}]")
    if added:
        lines.append("    add:")
        lines += [f"      - {_flow(o)}" for o in added]
    obstacles = [o for c in changes if c["kind"] == "obstacles" for o in c["obstacles"]]
    if obstacles:
        lines.append("    obstacles:")
        lines += [f"      - {_obstacle_flow(o)}" for o in obstacles]
    if not (overrides or removed or added or obstacles):  # pragma: no cover - draw_variant always changes something
        raise ValueError("a variant that changes nothing")
    return "\n".join(lines) + "\n"


def _nominal_obstacles(scene: Any) -> list[Any]:
    """The entries of the scene file's ``obstacles:`` as written (already checked when the scene loaded)."""
    import yaml

    return list((yaml.safe_load(Path(scene.path).read_text(encoding="utf-8")) or {}).get("obstacles") or [])


def _obstacle_flow(entry: dict[str, Any]) -> str:
    return "{" + ", ".join(f"{k}: {json.dumps(v) if isinstance(v, list) else v}" for k, v in entry.items()) + "}"


def _change_text(change: dict[str, Any]) -> str:
    if change["kind"] == "obstacles":
        items = ", ".join(f"{o['shape']} at {o['pose'][0]} {o['pose'][1]}" for o in change["obstacles"])
        return f"obstacles ({items}{', near ' + change['near'] if change.get('near') else ''})"
    def text(value: Any) -> str:
        return " ".join(str(v) for v in value) if isinstance(value, (list, tuple)) else str(value)

    rest = ", ".join(f"{k} {text(v)}" for k, v in change.items() if k != "kind" and v is not None)
    return f"{change['kind']} ({rest})"


def generate(chosen: Any, n: int, seed: int, out: str | Path, *, spec_path: str | Path | None = None,
             scene_path: str | Path | None = None, progress: Callable[[int, int], None] | None = None,
             robot: str | None = None) -> dict[str, Any]:
    """Write ``n`` variants of a family (a :class:`~bt_meta.campaign.families.CampaignFamily` or a shipped
    family's name) into ``out`` with their expected outcomes for ``robot`` (default the grounding's); returns the
    manifest. Everything is written into a temporary folder beside ``out`` and renamed when complete: a failure
    leaves nothing behind."""
    import shutil
    import tempfile

    from bt_meta.campaign.families import family, scene_of
    from bt_meta.campaign.labeller import Labeller
    from bt_meta.campaign.manifest import new_manifest, write_manifest
    from bt_meta.campaign.spec import load_spec
    from bt_meta.world.simulation.catalogue import object_types
    from bt_meta.world.simulation.scenes import load_scene
    from bt_meta.world.simulation.sim import Table
    from bt_meta.world.simulation.sim_world import load_grounding

    if isinstance(chosen, str):
        chosen = family(chosen)
    out = Path(out)
    if scene_path is not None:
        scene = load_scene(scene_path)
    else:
        from bt_meta.htn import load_task_file

        scene = scene_of(chosen, load_grounding(load_task_file(chosen.task_path()).domain.name, chosen.task_path()))
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    types = _TYPES.set(object_types(scene.catalogues))
    try:
        folder = staging / "variants"
        folder.mkdir()
        nominal = placed_objects(scene)
        entries = []
        with Labeller(chosen, scene, robot=robot) as labeller:
            if not labeller.plan:
                from bt_meta.errors import UserInputError

                raise UserInputError(f"problem {chosen.problem!r} has no plan: nothing to perturb",
                                     chosen.task_path())
            objects = {o.name: (o.type, o.model().role) for o in scene.objects}
            roles = {"grasped": list(labeller.grasped), "needed": list(labeller.needed)}
            spec = (load_spec(spec_path, objects, family=chosen.name, roles=roles) if spec_path is not None
                    else chosen.spec(objects, roles))
            # the labeller's targets are in the robot's base frame; the scene file's poses in the scene frame
            dx, dy, _ = labeller.sim.robot.scene_offset
            targets = [(x - dx, y - dy) for x, y, _ in labeller.targets]
            for k in range(n):
                objects_k, changes = draw_variant(nominal, spec, seed, k, targets=targets, table=Table().bounds)
                name = f"{chosen.name}_{seed}_{k:04d}"
                path = folder / f"{name}.yaml"
                path.write_text(scene_text(scene, name, objects_k, changes), encoding="utf-8")
                label = labeller.label(path, VARIANT_NAME, changes)
                path.write_text(scene_text(scene, name, objects_k, changes, label.expected, label.reason),
                                encoding="utf-8")
                entries.append({"name": name, "file": f"variants/{name}.yaml", "expected": label.expected,
                                "reason": label.reason, "changes": changes})
                if progress is not None:
                    progress(k + 1, n)
            robot_name = labeller.robot.name
        manifest = new_manifest(chosen, seed, spec, scene, entries, robot=robot_name, robot_file=robot)
        write_manifest(staging, manifest)
        if out.exists():
            if any(out.iterdir()):
                from bt_meta.campaign.manifest import CampaignDirError

                raise CampaignDirError("is not empty; choose another -o", out)
            out.rmdir()
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    finally:
        _TYPES.reset(types)
    return manifest
