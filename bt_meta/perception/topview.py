"""One look at the table from above: the image, its blocks and their grid-maps, and crops anywhere on demand.

Offers:

* :class:`TopView` -- an RGB(-D) top view with its projection, the detected :class:`~bt_meta.perception.hsv.Block`
  list, one grid-map per block, and :meth:`TopView.grid_map_at` for a window anywhere (what the grid-map
  expectation plugin compares a remembered crop with)
* :func:`analyse` -- a :class:`TopView` of an image array (synthetic images, recorded frames)
* :func:`capture` -- a :class:`TopView` from a :class:`bt_meta.world.simulation.camera.TopViewCamera` (or any camera
  with
  ``capture()`` and the simulator's table)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bt_meta.memory import GridMap
from bt_meta.perception.gridmap import DEFAULT_SPEC, GridSpec, block_grid_maps, grid_map_at
from bt_meta.perception.hsv import (
    DEFAULT_THRESHOLDS,
    Block,
    HSVThresholds,
    PlaneProjection,
    detect_blocks,
    nearest_block,
)

__all__ = ["TopView", "analyse", "capture"]

SURFACE_PATCH = 12
"""Pixels each side of the point whose depths' median is the surface there: about a block unit at the top camera's
2.5 mm a pixel, so studs and body top count as they do in a blob's ``top_z``."""
SURFACE_ITERATIONS = 4
"""Look-ups of the depth over a table point (each at the height the last one found): two settle it."""


@dataclass(eq=False)
class TopView:
    """A top view and what perception made of it. ``projection`` maps onto the table top; ``names`` (parallel to
    ``blocks``) are the world objects the blocks were matched to, when known."""

    rgb: np.ndarray
    projection: PlaneProjection
    blocks: list[Block]
    grid_maps: list[GridMap]
    depth: np.ndarray | None = None
    spec: GridSpec = DEFAULT_SPEC
    thresholds: HSVThresholds = DEFAULT_THRESHOLDS
    names: list[str | None] = field(default_factory=list)

    def grid_map_at(self, centre: Sequence[float], *, z: float | None = None, object_name: str | None = None,
                    colour: str | None = None, shape: str | None = None) -> GridMap:
        """The grid-map of the window around table point ``centre`` on the plane at height ``z`` (default:
        :meth:`surface_near`)."""
        if z is None:
            z = self.surface_near(centre)
        return grid_map_at(self.rgb, self.projection.at_height(z), centre, spec=self.spec,
                           thresholds=self.thresholds, object_name=object_name, colour=colour, shape=shape)

    def surface_near(self, centre: Sequence[float]) -> float:
        """The height a window around ``centre`` is read at: the surface the depth image shows over ``centre``
        (the top of the block lying there, the table where nothing does); without depth, the blocks' median top
        (the table top with no block). Not the median of every blob in view: a tall obstacle (a post) among a
        few blobs -- a finished letter merges into one -- pulls it up, and a window read at the wrong height is
        shifted in the perspective image (generated letters_A s1 0011); nor the blob nearest the centre, which a
        post beside a column of blocks can be when the column's blob is cut by it (letters_H s1 0016)."""
        z = float(np.median([b.top_z for b in self.blocks])) if self.blocks else self.projection.plane_z
        if self.depth is None:
            return z
        depth = np.asarray(self.depth, dtype=float)
        rows, cols = depth.shape[:2]
        for _ in range(SURFACE_ITERATIONS):  # the pixel over (x, y) depends on the height it is looked for at
            u, v = self.projection.at_height(z).table_to_pixel(np.array([centre[0]]), np.array([centre[1]]))
            col, row = int(np.floor(u[0])), int(np.floor(v[0]))
            if not (0 <= col < cols and 0 <= row < rows):
                return z
            patch = depth[max(row - SURFACE_PATCH, 0):row + SURFACE_PATCH + 1,
                          max(col - SURFACE_PATCH, 0):col + SURFACE_PATCH + 1]
            finite = patch[np.isfinite(patch)]
            if finite.size == 0:
                return z
            point = self.projection.pixel_to_point(u, v, np.array([float(np.median(finite))]))
            seen = float(point[0, 2])
            if abs(seen - z) < 0.001:
                return seen
            z = seen
        return z

    def block_near(self, point: Sequence[float], radius: float) -> Block | None:
        return nearest_block(self.blocks, point, radius)

    def name_of(self, block: Block) -> str | None:
        return self.names[block.index] if block.index < len(self.names) else None

    def describe(self) -> list[dict[str, Any]]:
        """The blocks as JSON-able dicts (with ``name`` when matched)."""
        out = []
        for block in self.blocks:
            entry = block.as_dict()
            entry["name"] = self.name_of(block)
            out.append(entry)
        return out


def analyse(
    rgb: np.ndarray,
    projection: PlaneProjection,
    *,
    depth: np.ndarray | None = None,
    thresholds: HSVThresholds = DEFAULT_THRESHOLDS,
    spec: GridSpec = DEFAULT_SPEC,
    namer: Any = None,
) -> TopView:
    """Detect the blocks of ``rgb`` and build their grid-maps. ``namer(block) -> str | None`` names blocks
    (e.g. after the simulator's objects); unnamed maps are called ``b<index>``."""
    blocks = detect_blocks(rgb, projection, depth=depth, thresholds=thresholds)
    names = [namer(block) if namer is not None else None for block in blocks]
    maps = block_grid_maps(rgb, projection, blocks, spec=spec, thresholds=thresholds,
                           names=[n or f"b{b.index}" for n, b in zip(names, blocks, strict=True)])
    return TopView(rgb, projection, blocks, maps, depth, spec, thresholds, names)


def capture(
    camera: Any,
    *,
    thresholds: HSVThresholds = DEFAULT_THRESHOLDS,
    spec: GridSpec = DEFAULT_SPEC,
    use_depth: bool = True,
    namer: Any = None,
) -> TopView:
    """Render one frame of ``camera`` (without segmentation: perception does not peek) and analyse it."""
    image = camera.capture(depth=use_depth, segmentation=False)
    projection = PlaneProjection.from_image(image, camera.sim.table.top_z)
    return analyse(image.rgb, projection, depth=image.depth if use_depth else None, thresholds=thresholds,
                   spec=spec, namer=namer)
