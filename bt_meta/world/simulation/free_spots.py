"""Free spots on the table: where a part can be put down clear of everything else.

A grounding file names a scene anchor where a part is set down (the re-orientations' ``set_down_spot``); a scene
with something lying on or beside that anchor (a distractor, a spare part) made the part land on it and tip over
(generated housing variant 0011: a distractor block 2.5 cm from the spot, the turned housing never stood up).
The world grounds an anchor pose at the nearest spot around the anchor where the part's footprint keeps a margin
to every other footprint, and stays on the table.

Offers:

* :func:`nearest_free_spot` -- the anchor itself when it is clear, else the nearest clear point around it
* :func:`clearance` -- how far a disc's edge is from the nearest footprint (negative: they overlap)
* :data:`MARGIN`, :data:`RING_STEP`, :data:`MAX_SHIFT` -- the search's defaults (metres)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["MARGIN", "MAX_SHIFT", "RING_STEP", "clearance", "nearest_free_spot"]

MARGIN = 0.015
"""Kept between the part's footprint and any other (a part let go turns a little as it lands)."""
RING_STEP = 0.02
MAX_SHIFT = 0.20
"""Farther than this from the anchor a spot is another place, not the one the grounding file meant."""
_ANGLES = 16


def _distance_to_polygon(point: np.ndarray, hull: np.ndarray) -> float:
    """Distance from ``point`` to the convex polygon ``hull`` (vertices in counter-clockwise order); 0 inside."""
    inside = True
    best = math.inf
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        edge = b - a
        if edge[0] * (point[1] - a[1]) - edge[1] * (point[0] - a[0]) < 0.0:
            inside = False
        length = float(edge @ edge)
        t = 0.0 if length == 0.0 else min(1.0, max(0.0, float((point - a) @ edge) / length))
        best = min(best, float(np.linalg.norm(point - (a + t * edge))))
    return 0.0 if inside else best


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2-D ``points``, counter-clockwise (monotone chain)."""
    pts = sorted({(round(float(x), 9), round(float(y), 9)) for x, y in points})
    if len(pts) <= 2:
        return np.array(pts, dtype=float)

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0.0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0.0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1], dtype=float)


def clearance(centre: Sequence[float], radius: float, hulls: Sequence[np.ndarray]) -> float:
    """The gap between a disc (``centre``, ``radius``) and the nearest of ``hulls`` (convex footprints);
    ``inf`` with none, negative where they overlap."""
    point = np.asarray(centre, dtype=float)[:2]
    gaps = [(_distance_to_polygon(point, h) if len(h) >= 3 else float(np.min(np.linalg.norm(h - point, axis=1))))
            - radius for h in hulls if len(h)]
    return min(gaps, default=math.inf)


def nearest_free_spot(anchor: Sequence[float], radius: float, footprints: Sequence[np.ndarray],
                      table: tuple[tuple[float, float], tuple[float, float]], *, margin: float = MARGIN,
                      step: float = RING_STEP, most: float = MAX_SHIFT, prefer: Sequence[float] | None = None,
                      accept: Callable[[float, float], bool] | None = None) -> tuple[float, float] | None:
    """The point nearest ``anchor`` (x, y) where a part of footprint radius ``radius`` keeps ``margin`` from every
    footprint (2-D points of each other object's outline) and, if it is not the anchor, lies on the ``table``
    ((x_min, x_max), (y_min, y_max)) and passes ``accept`` (the arm reaches it); the anchor itself when it is
    clear, else ``prefer`` (the spot chosen before) when it still is. Candidates: rings ``step`` apart up to
    ``most``, sixteen points each. ``None`` when none will do (the caller keeps the anchor: the physics then says
    what happens)."""
    hulls = [_hull(np.asarray(f, dtype=float)[:, :2]) for f in footprints if len(f)]
    (x_low, x_high), (y_low, y_high) = table
    ax, ay = float(anchor[0]), float(anchor[1])

    def clear(x: float, y: float) -> bool:
        on_table = x_low + radius <= x <= x_high - radius and y_low + radius <= y <= y_high - radius
        return on_table and clearance((x, y), radius, hulls) >= margin and (accept is None or accept(x, y))

    if clearance((ax, ay), radius, hulls) >= margin:  # where the grounding file says, if nothing is in the way
        return ax, ay
    if prefer is not None and clear(float(prefer[0]), float(prefer[1])):
        return float(prefer[0]), float(prefer[1])
    for ring in range(1, round(most / step) + 1):
        r = ring * step
        for k in range(_ANGLES):
            angle = 2.0 * math.pi * k / _ANGLES
            x, y = ax + r * math.cos(angle), ay + r * math.sin(angle)
            if clear(x, y):
                return x, y
    return None
