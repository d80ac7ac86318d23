"""The geometric check kinds a success check is made of, each decided on the simulator's true state.

A check reads the world's simulator (object transforms, the grasps, the magnet joins, the robot's links) and
the grounding (what a task-file symbol is in the world, where a frame's cell or a pose symbol is) -- never what
the run believed. Each kind takes task-file symbols as arguments; a symbol whose object is gone fails the check.

Offers:

* :data:`KINDS` -- kind -> (its arguments, its options with defaults, one line saying what holds)
* :func:`evaluate` -- ``(ok, reason)`` of one kind with its arguments and options in a world
* :func:`footprint` / :func:`covered` -- an object's outline on the table and the coverage test of ``at_cell``
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["KINDS", "CheckFailed", "covered", "evaluate", "footprint"]

#: kind -> (argument names, "..." for any number; options -> default; what holds)
KINDS: dict[str, tuple[tuple[str, ...], dict[str, Any], str]] = {
    "held": (("object",), {}, "the object is in the gripper (or joined to what is)"),
    "gripper": (("state",), {}, "closed: the gripper holds something; open: it holds nothing"),
    "lifted": (("...",), {"margin": 0.01},
               "every object hangs at least `margin` m above the table, held or joined to what is held"),
    "attached": (("object", "other"), {}, "the two objects are joined (directly or through other joins)"),
    "inserted": (("object", "feature"), {"tolerance": 0.01, "angle": 15.0},
                 "the object's primary feature is within `tolerance` m of the feature, normals opposed within "
                 "`angle` degrees"),
    "at_cell": (("object", "x", "y"), {"frame": None, "tolerance": 0.015, "gap": 0.005},
                "the object's outline laid at cell (x, y) of the frame is covered by objects resting on the table "
                "(any object: a stand-in may fill it), every point more than `tolerance` m inside the outline "
                "within `gap` m of one"),
    "at_pose": (("pose",), {"tolerance": 0.02},
                "the gripper is within `tolerance` m of the pose symbol, and the objects its `verify_lifted` "
                "lists are lifted"),
    "on_face": (("object", "axis"), {"angle": 20.0},
                "the object's axis (+x, -x, +y, -y, +z, -z of its model) points up within `angle` degrees"),
    "ignore": (("...",), {}, "nothing: the predicate says nothing about the world (bookkeeping of the plan)"),
}

_AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}


class CheckFailed(Exception):
    """A check that cannot be decided as written (a symbol the world cannot ground): it does not hold."""


def evaluate(kind: str, args: Sequence[str], options: Mapping[str, Any], world: Any) -> tuple[bool, str]:
    """Whether check ``kind`` of ``args`` holds in ``world`` now, and why."""
    try:
        return _CHECKS[kind](world, [str(a) for a in args], {**KINDS[kind][1], **options})
    except CheckFailed as error:
        return False, str(error)


def _object(world: Any, symbol: str) -> str:
    try:
        return str(world.object_name(symbol))
    except Exception:  # the symbol's object is gone (removed, never there): the check cannot hold
        raise CheckFailed(f"there is no object for {symbol!r} in the world") from None


def _arms(world: Any) -> list[str]:
    return list(world.sim.robot.arms)


def _held_group(world: Any) -> set[str]:
    """What the robot holds and everything joined to it, transitively."""
    sim = world.sim
    group = {h for arm in _arms(world) if (h := sim.held(arm)) is not None}
    joins = sim.attachments()
    grown = True
    while grown:
        grown = False
        for a, b in joins:
            if (a in group) != (b in group):
                group |= {a, b}
                grown = True
    return group


def _joined(world: Any, first: str, second: str) -> bool:
    group, joins = {first}, world.sim.attachments()
    grown = True
    while grown:
        grown = False
        for a, b in joins:
            if (a in group) != (b in group):
                group |= {a, b}
                grown = True
    return second in group


def _held(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    name = _object(world, args[0])
    if name in _held_group(world):
        return True, f"{name} is held"
    return False, f"{name} is not held"


def _gripper(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    state = args[0]
    if state not in ("open", "closed"):
        raise CheckFailed(f"gripper: the state is open or closed, not {state!r}")
    holding = [h for arm in _arms(world) if (h := world.sim.held(arm)) is not None]
    if state == "closed":
        return (True, f"the gripper holds {holding[0]}") if holding else (False, "the gripper holds nothing")
    return (False, f"the gripper still holds {holding[0]}") if holding else (True, "the gripper holds nothing")


def _lifted(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    names = [_object(world, a) for a in args]
    group = _held_group(world)
    top = float(world.sim.table.top_z)
    low = [n for n in names if float(world.object_lowest(n)) - top < float(options["margin"])]
    loose = [n for n in names if n not in group]
    if low:
        return False, f"{', '.join(low)} still on the table"
    if loose:
        return False, f"{', '.join(loose)} off the table but not held nor joined to what is held"
    return True, f"{', '.join(names)} lifted together"


def _attached(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    first, second = _object(world, args[0]), _object(world, args[1])
    if _joined(world, first, second):
        return True, f"{first} and {second} are joined"
    return False, f"{first} and {second} are not joined"


def _inserted(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    part = _object(world, args[0])
    try:
        target, feature = world.feature_of(args[1])
    except Exception:
        raise CheckFailed(f"there is no feature for {args[1]!r} in the world") from None
    sim = world.sim
    hole, hole_normal = sim.feature(target, feature)
    end, end_normal = sim.feature(part)
    distance = float(np.linalg.norm(np.asarray(end) - np.asarray(hole)))
    angle = math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(end_normal, hole_normal))))))
    if distance <= float(options["tolerance"]) and 180.0 - angle <= float(options["angle"]):
        return True, f"{part} is in {target}'s {feature or 'feature'} ({distance * 1000:.1f} mm)"
    return False, (f"{part} is not in {target}'s {feature or 'feature'}: {distance * 1000:.1f} mm away, normals "
                   f"{angle:.0f} deg apart (180 expected)")


def footprint(points: np.ndarray) -> np.ndarray:
    """The outline of 3-D points seen from above: the (k, 3) half-planes ``a x + b y + c <= 0`` of their convex
    hull in x, y (unit normals, so ``a x + b y + c`` is the signed distance inside and a lower bound outside)."""
    from scipy.spatial import ConvexHull

    flat = np.asarray(points, dtype=float)[:, :2]
    return np.asarray(ConvexHull(flat).equations, dtype=float)


def covered(target: np.ndarray, outlines: Sequence[np.ndarray], tolerance: float, gap: float,
            spacing: float = 0.004) -> tuple[int, int]:
    """(covered, total) sample points of the outline of ``target`` (3-D points) more than ``tolerance`` inside its
    edge (its centroid when none is that deep), each covered when it lies within ``gap`` of one of ``outlines``
    (half-planes from :func:`footprint`)."""
    flat = np.asarray(target, dtype=float)[:, :2]
    edges = footprint(target)
    low, high = flat.min(axis=0), flat.max(axis=0)
    xs, ys = np.arange(low[0], high[0] + spacing, spacing), np.arange(low[1], high[1] + spacing, spacing)
    grid = np.array([(x, y) for x in xs for y in ys])
    inside = grid[np.max(grid @ edges[:, :2].T + edges[:, 2], axis=1) <= -tolerance]
    if not len(inside):
        inside = flat.mean(axis=0, keepdims=True)
    hit = np.zeros(len(inside), dtype=bool)
    for outline in outlines:
        hit |= np.max(inside @ outline[:, :2].T + outline[:, 2], axis=1) <= gap
    return int(hit.sum()), len(inside)


def _frame(world: Any, options: dict[str, Any]) -> str:
    frames = list(getattr(world.grounding, "frames", {}) or {})
    if options.get("frame"):
        if options["frame"] not in frames:
            raise CheckFailed(f"at_cell: no frame {options['frame']!r} in the grounding; frames: "
                              f"{', '.join(frames) or 'none'}")
        return str(options["frame"])
    if len(frames) != 1:
        raise CheckFailed(f"at_cell: the grounding has {len(frames)} frames ({', '.join(frames) or 'none'}): name "
                          "one with `frame:`")
    return frames[0]


def _model(world: Any, symbol: str) -> Any:
    """The object model whose outline a cell of ``symbol`` has: the scene's nominal object of that name (what the
    task means by the symbol, even when a variant changed or removed it), else the world's object."""
    name = world.grounding.objects.get(symbol, symbol)
    for obj in getattr(world.scene, "objects", ()):
        if obj.name == name:
            return obj.model()  # its type as the scene's catalogue defines it
    if name in world.sim.object_names():
        return world.sim.object_model(name)
    raise CheckFailed(f"at_cell: no object {name!r} in the scene nor in the world to take the cell's outline from")


def _cell_floor(world: Any, frame: str, target: np.ndarray) -> tuple[float | None, str | None]:
    """(height, support) a part in a cell of ``frame`` rests on, as the place skill puts it there: the top of the
    frame's ``support:`` under the cell (a tray's floor, the block a part is stacked on; ``None`` when the support
    is not under it), else the table top (an anchor's own height is a surface the scene does not model: what is
    set down there lands on the table). A cell is filled by what rests there, not by the support itself nor by a
    part on the table under a stacked cell."""
    floor, support = world.frame_support(frame)
    if support is None:
        return float(world.sim.table.top_z), None
    low, high = target[:, :2].min(axis=0), target[:, :2].max(axis=0)
    centre, half = (low + high) / 2.0, 0.25 * (high - low)  # the middle of the cell, as place takes its floor
    middle = np.array([centre + (u, v) * half for u, v in ((0, 0), (1, 1), (-1, 1), (1, -1), (-1, -1))])
    top = world.surface_under(support, middle)
    return (None if top is None else max(float(top), float(floor))), support


def _at_cell(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    from bt_meta.world.simulation.objects import rpy_to_matrix

    frame = _frame(world, options)
    gx, gy, yaw = world.ground_cell(frame, args[1], args[2])
    model = _model(world, args[0])
    rotation = rpy_to_matrix(0.0, 0.0, float(yaw))
    target = model.points() @ rotation.T + np.array([gx, gy, 0.0])
    sim = world.sim
    floor, support = _cell_floor(world, frame, target)
    where = f"cell ({args[1]}, {args[2]}) of {frame}"
    if floor is None:
        return False, f"{where}: its support {support} is not under it"
    held = _held_group(world)
    outlines = []
    for name in sim.object_names():
        if name in held or name == support or abs(float(world.object_lowest(name)) - floor) > 0.01:
            continue
        t = sim.object_transform(name)
        outlines.append(footprint(sim.object_model(name).points() @ t[:3, :3].T + t[:3, 3]))
    hit, total = covered(target, outlines, float(options["tolerance"]), float(options["gap"]))
    if hit == total:
        return True, f"{where} is covered"
    return False, f"{where} is not covered ({total - hit} of {total} points of its outline bare)"


def _at_pose(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    symbol = args[0]
    try:
        spec = world.pose_spec(symbol)
        goal = np.asarray(world.ground_pose(symbol), dtype=float)
    except Exception as error:
        raise CheckFailed(f"the pose {symbol!r} cannot be grounded: {error}") from None
    arm = world.default_arm
    now = world.sim.link_transform(world.end_effector(arm))
    distance = float(np.linalg.norm(now[:3, 3] - goal[:3, 3]))
    if distance > float(options["tolerance"]):
        return False, f"the gripper is {distance * 100:.1f} cm from {symbol}"
    verify = [str(o) for o in spec.get("verify_lifted", ()) or ()]
    if verify:
        ok, why = _lifted(world, verify, {"margin": KINDS["lifted"][1]["margin"]})
        if not ok:
            return False, f"at {symbol}, but {why}"
        return True, f"at {symbol}; {why}"
    return True, f"the gripper is at {symbol}"


def _on_face(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    name = _object(world, args[0])
    if args[1] not in _AXES:
        raise CheckFailed(f"on_face: the axis is one of {', '.join(_AXES)}, not {args[1]!r}")
    index, sign = _AXES[args[1]]
    axis = sign * world.sim.object_transform(name)[:3, index]
    angle = math.degrees(math.acos(max(-1.0, min(1.0, float(axis[2])))))
    if angle <= float(options["angle"]):
        return True, f"{name}'s {args[1]} points up ({angle:.0f} deg)"
    return False, f"{name}'s {args[1]} is {angle:.0f} deg off up"


def _ignore(world: Any, args: list[str], options: dict[str, Any]) -> tuple[bool, str]:
    return True, "not a fact about the world"


_CHECKS = {"held": _held, "gripper": _gripper, "lifted": _lifted, "attached": _attached, "inserted": _inserted,
           "at_cell": _at_cell, "at_pose": _at_pose, "on_face": _on_face, "ignore": _ignore}
