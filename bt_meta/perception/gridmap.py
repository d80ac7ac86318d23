"""Grid-maps (paper, section 6.3): a 3 lb x 3 lb window centred on a block, quantised at 0.5 lb into 6 x 6 cells.

A cell is occupied when a block colour covers at least ``fill`` of it on the uniform table background; its value
is the colour's code (1 + the colour's position in the thresholds, 0 = empty), so the binary occupancy the
memory's nearest-neighbour search compares is ``grid != 0`` and the colour is still there for whoever wants it.
The window is axis-aligned with the table (row 0 = the far edge, +x; column 0 = the robot's left, +y), like
:meth:`bt_meta.world.simulation.camera.TopViewCamera.table_patch`, and is resampled from the image through the camera's
pinhole model, so it is metric and exact under perspective. The crop image is kept with it (BGR, as OpenCV
writes PNGs), as the paper's visual expectation.

Offers:

* :class:`GridSpec` -- cells, cell size, crop pixels per cell, fill fraction (defaults: the paper's 6 x 6 at
  0.5 lb, 8 pixels per cell, half a cell)
* :func:`table_crop` -- the metric RGB crop of the table plane around a point
* :func:`occupancy` -- the coded occupancy grid of a crop
* :func:`grid_map_at` -- a :class:`bt_meta.memory.GridMap` (occupancy + PNG crop) around a table point
* :func:`block_grid_maps` -- one grid-map per detected block, centred on its centroid at its top surface
* :func:`grid_difference` -- cells that differ (binary occupancy; optionally the best quarter turn)
* :func:`render` -- a grid as text (``.`` empty, ``r``/``b``/... the colour's first letter)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from bt_meta.memory import GridMap, grid_distance
from bt_meta.perception.hsv import (
    DEFAULT_THRESHOLDS,
    Block,
    HSVThresholds,
    PerceptionConfigError,
    PlaneProjection,
    colour_masks,
)
from bt_meta.world.simulation.objects import LB

__all__ = [
    "DEFAULT_SPEC",
    "GridSpec",
    "block_grid_maps",
    "grid_difference",
    "grid_map_at",
    "occupancy",
    "render",
    "table_crop",
]


@dataclass(frozen=True)
class GridSpec:
    """``cells`` x ``cells`` cells of ``cell_size`` metres; crops sampled at ``pixels_per_cell``; a cell is occupied
    when at least ``fill`` of its pixels show a block colour."""

    cells: int = 6
    cell_size: float = 0.5 * LB
    pixels_per_cell: int = 8
    fill: float = 0.5

    def __post_init__(self) -> None:
        if self.cells < 1 or self.pixels_per_cell < 1:
            raise PerceptionConfigError(f"a grid needs >= 1 cell and pixel per cell, got {self.cells}, "
                                        f"{self.pixels_per_cell}")
        if self.cell_size <= 0:
            raise PerceptionConfigError(f"grid cell size must be positive, got {self.cell_size}")
        if not 0.0 < self.fill <= 1.0:
            raise PerceptionConfigError(f"grid fill fraction must be in (0, 1], got {self.fill}")

    @property
    def window(self) -> float:
        """Side of the window in metres (3 lb for the paper's grid)."""
        return self.cells * self.cell_size

    @property
    def pixels(self) -> int:
        return self.cells * self.pixels_per_cell


DEFAULT_SPEC = GridSpec()


def table_crop(
    rgb: np.ndarray, projection: PlaneProjection, centre: Sequence[float], spec: GridSpec = DEFAULT_SPEC
) -> np.ndarray:
    """The RGB crop of ``projection``'s plane, ``spec.window`` wide around table point ``centre`` = (x, y).

    Pixels outside the image are black (no colour: empty cells)."""
    n = spec.pixels
    step = spec.window / n
    offsets = (np.arange(n) + 0.5) * step - spec.window / 2.0
    rows, cols = np.meshgrid(offsets, offsets, indexing="ij")
    us, vs = projection.table_to_pixel(centre[0] - rows, centre[1] - cols)
    # Pixel centres are at +0.5: remap indexes pixels by their integer position.
    return cv2.remap(np.ascontiguousarray(rgb), (us - 0.5).astype(np.float32), (vs - 0.5).astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def occupancy(crop: np.ndarray, spec: GridSpec = DEFAULT_SPEC,
              thresholds: HSVThresholds = DEFAULT_THRESHOLDS) -> np.ndarray:
    """The ``cells x cells`` uint8 grid of a crop made by :func:`table_crop`: each occupied cell holds the code of
    the colour covering most of it."""
    if crop.shape[:2] != (spec.pixels, spec.pixels):
        raise ValueError(f"crop is {crop.shape[:2]}, the grid spec samples {spec.pixels} x {spec.pixels}")
    # No morphological opening here: a thin strip of a neighbour at the window border is still colour.
    plain = HSVThresholds(thresholds.colours, thresholds.min_pixels, 0)
    masks = colour_masks(crop, plain)
    k, c = spec.pixels_per_cell, spec.cells
    fractions = np.stack([m.reshape(c, k, c, k).mean(axis=(1, 3)) for m in masks.values()])
    total = fractions.sum(axis=0)
    codes = fractions.argmax(axis=0).astype(np.uint8) + 1
    return np.where(total >= spec.fill, codes, 0).astype(np.uint8)


def grid_map_at(
    rgb: np.ndarray,
    projection: PlaneProjection,
    centre: Sequence[float],
    *,
    spec: GridSpec = DEFAULT_SPEC,
    thresholds: HSVThresholds = DEFAULT_THRESHOLDS,
    object_name: str | None = None,
    colour: str | None = None,
    shape: str | None = None,
) -> GridMap:
    """The grid-map of the window around ``centre`` on ``projection``'s plane, with its crop as a PNG (BGR)."""
    crop = table_crop(rgb, projection, centre, spec)
    return GridMap(
        occupancy(crop, spec, thresholds),
        image=cv2.cvtColor(crop, cv2.COLOR_RGB2BGR),
        object_name=object_name,
        colour=colour,
        shape=shape,
        centroid=(float(centre[0]), float(centre[1])),
    )


def block_grid_maps(
    rgb: np.ndarray,
    projection: PlaneProjection,
    blocks: Sequence[Block],
    *,
    spec: GridSpec = DEFAULT_SPEC,
    thresholds: HSVThresholds = DEFAULT_THRESHOLDS,
    names: Sequence[str | None] | None = None,
) -> list[GridMap]:
    """One grid-map per block, centred on its centroid and sampled on the plane of its top surface (so a block's
    top face lands on its own footprint); ``names`` gives each map an object name (default ``b<index>``)."""
    if names is not None and len(names) != len(blocks):
        raise ValueError(f"{len(names)} names for {len(blocks)} blocks")
    maps = []
    for i, block in enumerate(blocks):
        name = names[i] if names is not None else f"b{block.index}"
        maps.append(grid_map_at(rgb, projection.at_height(block.top_z), block.centroid, spec=spec,
                                thresholds=thresholds, object_name=name, colour=block.colour, shape=block.shape))
    return maps


def grid_difference(expected: np.ndarray | GridMap, observed: np.ndarray | GridMap, *, rotations: bool = False) -> int:
    """Number of cells whose occupancy differs (colour ignored); with ``rotations`` the best quarter turn of
    ``observed`` counts (the memory's retrieval metric)."""
    a = expected.occupancy if isinstance(expected, GridMap) else np.asarray(expected)
    b = observed.occupancy if isinstance(observed, GridMap) else np.asarray(observed)
    if a.shape != b.shape:
        raise ValueError(f"grid-maps of different shapes: {a.shape} and {b.shape}")
    return grid_distance(b, a, rotations=rotations)[0]


def render(grid: np.ndarray | GridMap, thresholds: HSVThresholds = DEFAULT_THRESHOLDS) -> str:
    """The grid as lines of text: ``.`` empty, else the first letter of the cell's colour (``#`` for codes the
    thresholds do not name)."""
    cells = grid.occupancy if isinstance(grid, GridMap) else np.asarray(grid)
    names = thresholds.names
    letters = {0: "."}
    letters.update({i + 1: name[0] for i, name in enumerate(names)})
    return "\n".join("".join(letters.get(int(v), "#") for v in row) for row in cells)
