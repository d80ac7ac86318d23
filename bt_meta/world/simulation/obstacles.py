"""Static obstacles of a scene: boxes, walls, posts and shelves the robot must keep clear of.

An obstacle is not an object of the task: it has no attachment features, perception plugins and traces do not
list it, and skills never grasp it. The simulator makes it a static body (the cameras see it, the physics stops
the arm on it) and the SimWorld puts the same shapes into the collision checker, so IK and path checks report a
pose or path that runs into it as ``collision``.

Every obstacle frame has its origin at the centre of the obstacle's footprint, on its underside: a scene pose
with ``z: table`` stands it on the table top.

Offers:

* :data:`OBSTACLE_SHAPES` -- shape name -> the dimension keys it takes
* :func:`obstacle_model` -- the static :class:`~bt_meta.world.simulation.objects.ObjectModel` of a shape
* :class:`ObstacleError` -- a shape or dimension that cannot be built
"""

from __future__ import annotations

from collections.abc import Mapping

from bt_meta.errors import BtMetaError
from bt_meta.world.simulation.objects import AttachmentFeature, Box, Cylinder, ObjectModel, Part

__all__ = ["OBSTACLE_SHAPES", "ObstacleError", "obstacle_model"]

OBSTACLE_SHAPES: dict[str, tuple[str, ...]] = {
    "box": ("size",),  # [x, y, z]
    "wall": ("size",),  # [length (x), thickness (y), height (z)]
    "post": ("radius", "height"),
    "shelf": ("size", "thickness"),  # outer [x, y, z]; two side panels at the y ends and a top board
}
"""Shape name -> the dimension keys a scene file gives it (metres). ``thickness`` of a shelf is optional."""

SHELF_THICKNESS = 0.02


class ObstacleError(BtMetaError):
    """An obstacle shape that does not exist or dimensions it cannot be built with."""


def obstacle_model(shape: str, dimensions: Mapping[str, object], colour: str = "grey") -> ObjectModel:
    """The static model of an obstacle ``shape`` with ``dimensions`` (see :data:`OBSTACLE_SHAPES`)."""
    if shape not in OBSTACLE_SHAPES:
        raise ObstacleError(f"unknown obstacle shape {shape!r}; known: {', '.join(OBSTACLE_SHAPES)}")
    parts: list[Part]
    if shape in ("box", "wall"):
        sx, sy, sz = _size(dimensions)
        parts = [Box((sx, sy, sz), (0.0, 0.0, sz / 2.0))]
        height = sz
    elif shape == "post":
        radius, height = _positive(dimensions, "radius"), _positive(dimensions, "height")
        parts = [Cylinder(radius, height, (0.0, 0.0, height / 2.0))]
    else:
        sx, sy, sz = _size(dimensions)
        thickness = _positive(dimensions, "thickness") if "thickness" in dimensions else SHELF_THICKNESS
        if 2.0 * thickness >= sy or thickness >= sz:
            raise ObstacleError(f"a shelf's thickness {thickness} must be less than half its width and its height")
        side = (sx, thickness, sz - thickness)
        parts = [
            Box(side, (0.0, -(sy - thickness) / 2.0, side[2] / 2.0)),
            Box(side, (0.0, (sy - thickness) / 2.0, side[2] / 2.0)),
            Box((sx, sy, thickness), (0.0, 0.0, sz - thickness / 2.0)),
        ]
        height = sz
    top = AttachmentFeature("top", (0.0, 0.0, height), (0.0, 0.0, 1.0))
    return ObjectModel(type=f"obstacle_{shape}", colour=colour, parts=tuple(parts), mass=0.0, features=(top,),
                       primary="top", info={"height": height})


def _positive(dimensions: Mapping[str, object], key: str) -> float:
    value = dimensions.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ObstacleError(f"{key} must be a positive number (metres), got {value!r}")
    return float(value)


def _size(dimensions: Mapping[str, object]) -> tuple[float, float, float]:
    value = dimensions.get("size")
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ObstacleError(f"size must be [x, y, z] (metres), got {value!r}")
    x, y, z = (_positive({"size": v}, "size") for v in value)
    return (x, y, z)
