"""Synthetic top views with exact answers: blocks drawn as filled footprints on a table-coloured canvas.

For tests and examples of perception plugins: the drawing goes through the same :class:`PlaneProjection` the
detector uses, with sub-pixel anti-aliased corners, so a block's centroid, orientation and shape are known to a
fraction of a pixel.

Offers:

* :data:`TABLE_RGB`, :data:`BLOCK_RGB` -- the simulator's table and block colours as 8-bit RGB
* :func:`top_view_projection` -- a straight-down 320 x 240 view, 2.5 mm per pixel, like the simulator's top camera
* :func:`blank` -- an empty table image
* :func:`draw_block` -- a 1x1 or 1x2 Mega Blok footprint at (x, y, yaw)
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from bt_meta.perception.hsv import PlaneProjection
from bt_meta.world.simulation.objects import COLOURS, LB

__all__ = ["BLOCK_RGB", "TABLE_RGB", "blank", "draw_block", "top_view_projection"]

TABLE_RGB = (222, 214, 198)
BLOCK_RGB: dict[str, tuple[int, int, int]] = {
    name: (round(rgba[0] * 255), round(rgba[1] * 255), round(rgba[2] * 255)) for name, rgba in COLOURS.items()}
"""Every colour the scene format accepts, as the simulator renders it fully lit."""


def top_view_projection(centre: tuple[float, float] = (0.70, -0.20), metres_per_pixel: float = 0.0025,
                        width: int = 320, height: int = 240) -> PlaneProjection:
    return PlaneProjection.top_down(width, height, centre, metres_per_pixel)


def blank(projection: PlaneProjection) -> np.ndarray:
    image = np.empty((projection.height, projection.width, 3), np.uint8)
    image[:] = TABLE_RGB
    return image


def draw_block(image: np.ndarray, projection: PlaneProjection, x: float, y: float, yaw: float, shape: str,
               colour: str) -> None:
    """Fill the footprint of a ``shape`` block (long axis at ``yaw`` from +x) centred on table point (x, y)."""
    length = {"1x1": 1, "1x2": 2}[shape] * LB
    axis = np.array([math.cos(yaw), math.sin(yaw)])
    normal = np.array([-axis[1], axis[0]])
    corners = [np.array([x, y]) + sx * axis * length / 2 + sy * normal * LB / 2
               for sx, sy in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
    us, vs = projection.table_to_pixel(np.array([c[0] for c in corners]), np.array([c[1] for c in corners]))
    shift = 8
    # Continuous pixel coordinates (centre of pixel [r, c] = (c + 0.5, r + 0.5)) -> OpenCV's integer-indexed ones.
    points = np.round(np.stack([us - 0.5, vs - 0.5], axis=1) * (1 << shift)).astype(np.int32)
    cv2.fillPoly(image, [points], BLOCK_RGB[colour], lineType=cv2.LINE_AA, shift=shift)
