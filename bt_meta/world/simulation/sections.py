"""Cross-sections of a part as it lies, from its collision shapes: where a parallel gripper's fingers close on it.

A friction grasp holds what its pads squeeze. Bounding boxes of a part's pieces say little about that once the part
is turned: the housing lying on its side is 24 tilted boxes whose boxes overlap every height, and the grasp they
gave closed the fingers on the narrow body next to the flange, on its curved top, so it turned in the fingers.
Here each convex piece (a box, a cylinder as a 32-sided prism, a mesh as its convex hull: what pybullet collides)
is a set of half-spaces, and the chord a line across the fingers cuts through the part is exact.

* :func:`chords` -- the span of the part along a direction, on many lines at once
* :func:`square_contact` -- how much of a pad's height meets faces square to it (not a slope or an edge)
* :func:`widest_section` -- where along the pads' width the part is widest across the fingers, and at what
  heights (the band of faces square to the pads)
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np

from bt_meta.world.simulation.objects import Box, Cylinder, Mesh, ObjectModel, Part, rpy_to_matrix

__all__ = ["Section", "chords", "half_spaces", "square_contact", "widest_section"]

WIDTH_TOLERANCE = 0.002
"""Chords within this (m) of the widest count as the widest (as for the pieces of a part standing upright)."""
STEP = 0.001
"""Spacing (m) of the lines sampled along the pads' width."""


@functools.lru_cache(maxsize=256)
def _piece_half_spaces(part: Part) -> tuple[np.ndarray, np.ndarray]:
    """(normals, offsets) of the piece in the object frame: inside where normals @ x <= offsets."""
    if isinstance(part, Box):
        half = np.asarray(part.size, float) / 2.0
        local_n = np.vstack([np.eye(3), -np.eye(3)])
        local_d = np.concatenate([half, half])
    elif isinstance(part, Cylinder):
        sides = 32
        angles = np.arange(sides) * 2.0 * math.pi / sides
        local_n = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(sides)])
        local_n = np.vstack([local_n, [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
        local_d = np.concatenate([np.full(sides, part.radius), [part.length / 2.0] * 2])
    elif isinstance(part, Mesh):
        from scipy.spatial import ConvexHull

        hull = ConvexHull(np.asarray(part.vertices, float))
        local_n, local_d = hull.equations[:, :3], -hull.equations[:, 3]
    else:  # pragma: no cover - Part is a closed union
        raise TypeError(f"no half-spaces for {part!r}")
    rotation = rpy_to_matrix(*part.rpy)
    normals = local_n @ rotation.T
    offsets = local_d + normals @ np.asarray(part.position, float)
    normals.setflags(write=False)
    offsets.setflags(write=False)
    return normals, offsets


def half_spaces(model: ObjectModel, transform: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each piece of ``model`` placed at ``transform``: (normals, offsets) in the base frame."""
    out = []
    rotation, origin = transform[:3, :3], transform[:3, 3]
    for part in model.parts:
        normals, offsets = _piece_half_spaces(part)
        world = normals @ rotation.T
        out.append((world, offsets + world @ origin))
    return out


def chords(pieces: list[tuple[np.ndarray, np.ndarray]], origins: np.ndarray, direction: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """(low, high): how far along ``direction`` from each of ``origins`` (n x 3) the part reaches on the line
    through it, the outermost of every piece the line crosses; NaN where it crosses none."""
    low = np.full(len(origins), np.inf)
    high = np.full(len(origins), -np.inf)
    for normals, offsets in pieces:
        slack = offsets[None, :] - origins @ normals.T  # n x h: t * (normal . direction) <= slack
        rate = normals @ direction
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = slack / rate[None, :]
        upper = np.where(rate[None, :] > 1e-12, bound, np.inf).min(axis=1)
        lower = np.where(rate[None, :] < -1e-12, bound, -np.inf).max(axis=1)
        parallel_out = ((np.abs(rate)[None, :] <= 1e-12) & (slack < 0.0)).any(axis=1)
        crosses = (upper >= lower) & ~parallel_out
        low = np.where(crosses, np.minimum(low, lower), low)
        high = np.where(crosses, np.maximum(high, upper), high)
    empty = ~np.isfinite(low)
    low[empty] = np.nan
    high[empty] = np.nan
    return low, high


@dataclass(frozen=True)
class Section:
    """Where fingers closing along ``axis`` meet the part at its widest: the point (x, y) their middle goes over
    and the band of heights [``low``, ``high``] (base frame z) where the part is that wide there; ``width`` across
    the fingers; ``moved`` when the point is not the one asked about (whose section is narrower)."""

    x: float
    y: float
    low: float
    high: float
    width: float
    moved: bool


def widest_section(model: ObjectModel, transform: np.ndarray, axis: np.ndarray, at: tuple[float, float]
                   ) -> Section | None:
    """The section of ``model`` (placed at ``transform``) a gripper closing along the horizontal ``axis`` holds
    best: at the point ``at`` (its grasp frame or centroid) when the part is as wide there as anywhere along the
    pads' width (within :data:`WIDTH_TOLERANCE`), else over the middle of the nearest stretch where it is (the
    flange of a housing lying on its side, not its narrower body). The band is the highest run of heights where
    the chord is the widest there: between the pieces' corner heights, so an upright part's band is its widest
    piece's, and a round section lying down has its band around its axis (above it the pads would meet a slope).
    ``None`` when ``axis`` is not horizontal enough to say, or the part has no extent."""
    a = np.array([axis[0], axis[1], 0.0], float)
    if float(np.linalg.norm(a)) < 0.5:
        return None
    a /= float(np.linalg.norm(a))
    b = np.array([-a[1], a[0], 0.0])
    pieces = half_spaces(model, transform)
    points = model.points() @ transform[:3, :3].T + transform[:3, 3]
    origin = np.array([at[0], at[1], 0.0])
    along = (points - origin) @ b
    heights = np.unique(np.round(points[:, 2], 9))
    if len(heights) < 2 or float(along.max() - along.min()) < 1e-9:
        return None
    # z samples: the middle of every interval between corner heights (a box's faces start and end there), and a
    # few more inside long intervals (a tilted face's chord changes along it)
    zs = np.concatenate([np.linspace(lo, hi, 6)[1:-1] if hi - lo > 0.004 else [(lo + hi) / 2.0]
                         for lo, hi in itertools.pairwise(heights)])
    cells = np.concatenate([np.full(6 - 2 if hi - lo > 0.004 else 1, k)
                            for k, (lo, hi) in enumerate(itertools.pairwise(heights))])
    ss = np.arange(math.floor(float(along.min()) / STEP), math.ceil(float(along.max()) / STEP) + 1) * STEP
    ss = np.union1d(ss, [0.0])
    grid_s, grid_z = np.meshgrid(ss, zs, indexing="ij")
    origins = origin + grid_s.reshape(-1, 1) * b + np.column_stack([np.zeros(grid_z.size)] * 2 + [grid_z.ravel()])
    low, high = chords(pieces, origins, a)
    width = np.nan_to_num(high - low, nan=0.0).reshape(len(ss), len(zs))
    widest_per_s = width.max(axis=1)
    widest = float(widest_per_s.max())
    if widest <= 0.0:
        return None
    good = widest_per_s >= widest - WIDTH_TOLERANCE
    here = int(np.flatnonzero(ss == 0.0)[0])
    moved = not bool(good[here])
    if moved:  # the middle of the nearest stretch of the widest section
        runs = np.split(np.flatnonzero(good), np.flatnonzero(np.diff(np.flatnonzero(good)) > 1) + 1)
        run = min(runs, key=lambda r: min(abs(float(ss[r[0]])), abs(float(ss[r[-1]]))))
        index = int(run[np.argmin(np.abs(ss[run] - 0.5 * (ss[run[0]] + ss[run[-1]])))])
    else:
        index = here
    column = width[index]
    wide = column >= float(column.max()) - WIDTH_TOLERANCE
    # the highest run of corner-height intervals whose chords are all the widest
    ok = np.array([bool(wide[cells == k].all()) if (cells == k).any() else False for k in range(len(heights) - 1)])
    top_cell = int(np.flatnonzero(ok)[-1]) if ok.any() else int(cells[int(np.argmax(column))])
    first = top_cell
    while first > 0 and ok[first - 1]:
        first -= 1
    band_low, band_high = float(heights[first]), float(heights[top_cell + 1])
    centre = origin + ss[index] * b
    if moved:  # centred between the fingers on that section (they close as mirror images)
        middle = origin + ss[index] * b + np.array([0.0, 0.0, 0.5 * (band_low + band_high)])
        lo, hi = chords(pieces, middle[None, :], a)
        if np.isfinite(lo[0]):
            centre = centre + 0.5 * float(lo[0] + hi[0]) * a
    return Section(float(centre[0]), float(centre[1]), band_low, band_high, float(column.max()), moved)


def square_contact(model: ObjectModel, transform: np.ndarray, axis: np.ndarray, at: tuple[float, float],
                   low: float, high: float, tolerance: float = 0.0005) -> float:
    """How much (m) of the heights [``low``, ``high``] (a finger pad's) over the point ``at`` meets the part where
    its chord across the fingers (``axis``) is within ``tolerance`` of the widest chord there: the faces the pads
    press on. A block's side or a standing housing's body gives the pad's full overlap with it; a round section
    lying down, touched above its axis, a fraction of a millimetre (the pads meet a slope)."""
    a = np.array([axis[0], axis[1], 0.0], float)
    if float(np.linalg.norm(a)) < 0.5 or high <= low:
        return 0.0
    a /= float(np.linalg.norm(a))
    zs = np.linspace(low, high, 81)
    origins = np.column_stack([np.full(zs.size, at[0]), np.full(zs.size, at[1]), zs])
    lo, hi = chords(half_spaces(model, transform), origins, a)
    width = np.nan_to_num(hi - lo, nan=0.0)
    if float(width.max()) <= 0.0:
        return 0.0
    return float((width >= width.max() - tolerance).sum() - 1) * (high - low) / (zs.size - 1)
