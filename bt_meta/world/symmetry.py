"""How an object looks turned about its own vertical axis: the yaw period of its shape and attachment features.

Grasps follow a part as it lies (a part turned by its period is grasped as it was), places and monitors check a
heading only up to it. Computed from the geometry, so a catalogue box, a cylinder or a mesh needs no label: a 1x1
Mega Blok or a square box 90 degrees, a 1x2 180 degrees, the housing's 12-sided tube 30 degrees, a cylinder its
outline's sampling step, a part with a feature off its axis (a magnet on a side face) 360 degrees.

Offers:

* :func:`yaw_period` -- the smallest turn about the object's z axis that maps its outline and features onto themselves
* :func:`heading_matters` -- whether a heading off by ``tolerance`` shows at all (the period is wider than twice it)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["heading_matters", "yaw_period"]

TOLERANCE = 5e-4
"""m: a turned outline point this close to one of the outline's own maps onto it."""
DIVISORS = (64, 48, 36, 32, 24, 16, 12, 8, 6, 4, 3, 2)
"""Turns tried, as fractions of a full turn (the finest first)."""

_cache: dict[int, tuple[Any, float]] = {}


def _rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _maps_onto(points: np.ndarray, turned: np.ndarray) -> bool:
    for start in range(0, len(turned), 256):
        chunk = turned[start:start + 256]
        nearest = np.min(np.linalg.norm(chunk[:, None, :] - points[None, :, :], axis=2), axis=1)
        if float(nearest.max()) > TOLERANCE:
            return False
    return True


def yaw_period(model: Any) -> float:
    """The smallest turn (rad) about the object's z axis, of a whole turn divided by one of :data:`DIVISORS`, that
    maps its outline points and its attachment features (point and normal) onto themselves; a whole turn when
    none does."""
    cached = _cache.get(id(model))
    if cached is not None and cached[0] is model:
        return cached[1]
    points = np.asarray(model.points(), dtype=float)
    features = [(np.asarray(f.point, float), np.asarray(f.normal, float)) for f in getattr(model, "features", ())]
    period = 2.0 * math.pi
    for n in DIVISORS:
        rotation = _rotation(2.0 * math.pi / n)
        if not _maps_onto(points, points @ rotation.T):
            continue
        if all(any(np.linalg.norm(rotation @ p - q) <= TOLERANCE and np.linalg.norm(rotation @ a - b) <= 1e-3
                   for q, b in features) for p, a in features):
            period = 2.0 * math.pi / n
            break
    _cache[id(model)] = (model, period)
    return period


def heading_matters(model: Any, tolerance: float) -> bool:
    """Whether a heading ``tolerance`` (rad) off can be told from the right one: the period is wider than twice it."""
    return yaw_period(model) > 2.0 * tolerance
