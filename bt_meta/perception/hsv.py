"""HSV blob detection on a top view of the table: Mega Bloks with colour, shape, centroid and orientation.

Section 6.3 of the paper: colour-threshold the top view in HSV, take each coloured blob as a block, decide its
shape by comparing the blob's axes with lb = 6.1 cm, and report its centroid and orientation in table
coordinates. Pixel geometry is turned into metric geometry *before* measuring, every pixel through the camera's
pinhole model, so shape and orientation do not depend on where in the image a block lies:

* with a depth image, each blob pixel becomes its 3-D point and only the block's upper surfaces are kept (points
  within ``surface_tolerance`` of the blob's median height or above): the side faces a perspective view shows
  near the image border are dropped, so the centroid is the footprint's; a blob lying below the plane (the floor
  beyond the table's edge, which a light grey or white matches) is no block;
* without depth (a plain RGB image, synthetic images), each pixel is intersected with the horizontal plane of
  the :class:`PlaneProjection` (the table top, or the blocks' top face when its height is known).

Offers:

* :class:`ColourRange`, :class:`HSVThresholds`, :data:`DEFAULT_THRESHOLDS` -- thresholds as data (OpenCV HSV:
  H 0..179, S and V 0..255); :meth:`HSVThresholds.from_mapping` reads them from a YAML/JSON mapping
* :func:`colour_masks` -- one boolean mask per colour
* :class:`PlaneProjection` -- vectorised pixel <-> table-plane conversion of a pinhole camera (the maths of
  :meth:`bt_meta.world.simulation.camera.Camera.pixel_to_plane`), from a captured image or a synthetic straight-down
  view
* :class:`Block` -- one detected block; :func:`detect_blocks` -- all blocks of an RGB(-D) image
* :func:`classify_shape` -- ``"1x1"``, ``"1x2"`` or ``"unknown"`` from metric axis lengths
* :func:`nearest_block` -- the detected block nearest a table point
* :class:`PerceptionConfigError` -- thresholds or settings that make no sense
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from bt_meta.errors import ConfigError
from bt_meta.world.simulation.objects import LB

__all__ = [
    "DEFAULT_THRESHOLDS",
    "Block",
    "ColourRange",
    "HSVThresholds",
    "PerceptionConfigError",
    "PlaneProjection",
    "classify_shape",
    "colour_masks",
    "detect_blocks",
    "nearest_block",
]


class PerceptionConfigError(ConfigError):
    """Perception thresholds or settings that make no sense (a range outside OpenCV's HSV, a negative area)."""


# -- thresholds ---------------------------------------------------------------------------------------------------

_HSV_MAX = (179, 255, 255)


@dataclass(frozen=True)
class ColourRange:
    """An inclusive OpenCV HSV box ``lower <= (h, s, v) <= upper`` (H 0..179, S, V 0..255)."""

    lower: tuple[int, int, int]
    upper: tuple[int, int, int]

    def __post_init__(self) -> None:
        for name in ("lower", "upper"):
            value = tuple(getattr(self, name))
            if len(value) != 3 or not all(isinstance(v, (int, np.integer)) for v in value):
                raise PerceptionConfigError(f"HSV {name} bound must be three integers (h, s, v), got {value!r}")
            for v, top, channel in zip(value, _HSV_MAX, "hsv", strict=True):
                if not 0 <= v <= top:
                    raise PerceptionConfigError(f"HSV {name} bound {value}: {channel} = {v} is outside 0..{top}")
            object.__setattr__(self, name, tuple(int(v) for v in value))
        if any(lo > hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise PerceptionConfigError(f"HSV range lower {self.lower} exceeds upper {self.upper}")


@dataclass(frozen=True)
class HSVThresholds:
    """Which HSV ranges count as which colour, and the smallest blob that counts as a block.

    A colour may have several ranges (red wraps around H = 0). ``min_pixels`` drops specks; ``open_kernel`` is
    the size of the morphological opening applied to each mask (0 or 1: none).
    """

    colours: Mapping[str, tuple[ColourRange, ...]]
    min_pixels: int = 20
    open_kernel: int = 3

    def __post_init__(self) -> None:
        if not self.colours:
            raise PerceptionConfigError("HSV thresholds need at least one colour")
        colours = {}
        for name, ranges in self.colours.items():
            if not isinstance(name, str) or not name:
                raise PerceptionConfigError(f"colour name {name!r} is not a non-empty string")
            ranges = tuple(ranges)
            if not ranges or not all(isinstance(r, ColourRange) for r in ranges):
                raise PerceptionConfigError(f"colour {name!r} needs one or more HSV ranges")
            colours[name] = ranges
        object.__setattr__(self, "colours", colours)
        if self.min_pixels < 1:
            raise PerceptionConfigError(f"min_pixels must be at least 1, got {self.min_pixels}")
        if self.open_kernel < 0:
            raise PerceptionConfigError(f"open_kernel must be >= 0, got {self.open_kernel}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.colours)

    def code(self, colour: str) -> int:
        """The grid-map cell value of ``colour``: 1 + its position among the colours (0 is empty)."""
        return self.names.index(colour) + 1

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], path: str | None = None) -> HSVThresholds:
        """Read ``{colours: {red: [[lower, upper], ...], ...}, min_pixels: 20, open_kernel: 3}``."""
        if not isinstance(data, Mapping) or "colours" not in data:
            raise PerceptionConfigError("HSV thresholds: expected a mapping with a 'colours' key", path)
        unknown = set(data) - {"colours", "min_pixels", "open_kernel"}
        if unknown:
            raise PerceptionConfigError(f"HSV thresholds: unknown keys {sorted(unknown)}", path)
        colours: dict[str, tuple[ColourRange, ...]] = {}
        spec = data["colours"]
        if not isinstance(spec, Mapping):
            raise PerceptionConfigError("HSV thresholds: 'colours' must map colour names to ranges", path)
        for name, ranges in spec.items():
            try:
                colours[str(name)] = tuple(ColourRange(tuple(lo), tuple(hi)) for lo, hi in ranges)
            except PerceptionConfigError as error:
                raise PerceptionConfigError(f"HSV thresholds, colour {name!r}: {error.message}", path) from None
            except (TypeError, ValueError):
                raise PerceptionConfigError(
                    f"HSV thresholds, colour {name!r}: expected a list of [lower, upper] pairs of (h, s, v)", path
                ) from None
        try:
            return cls(colours, int(data.get("min_pixels", 20)), int(data.get("open_kernel", 3)))
        except PerceptionConfigError as error:
            raise PerceptionConfigError(error.message, path) from None


DEFAULT_THRESHOLDS = HSVThresholds(
    {
        # Saturated, not too dark: a beige table (S ~ 28) and grey robot parts never pass S >= 120.
        "red": (ColourRange((0, 120, 60), (8, 255, 255)), ColourRange((172, 120, 60), (179, 255, 255))),
        "blue": (ColourRange((100, 120, 50), (130, 255, 255)),),
    }
)
"""Red and blue, the paper's block colours, for the simulator's renderings and ordinary lighting."""


def colour_masks(rgb: np.ndarray, thresholds: HSVThresholds = DEFAULT_THRESHOLDS) -> dict[str, np.ndarray]:
    """A boolean mask per colour of an RGB uint8 image (opened with the thresholds' kernel)."""
    image = np.asarray(rgb)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an H x W x 3 uint8 RGB image, got {image.dtype} {image.shape}")
    hsv = cv2.cvtColor(image, cv2.COLOR_RGB2HSV)
    kernel = None
    if thresholds.open_kernel > 1:
        kernel = np.ones((thresholds.open_kernel, thresholds.open_kernel), np.uint8)
    masks = {}
    for name, ranges in thresholds.colours.items():
        mask = np.zeros(image.shape[:2], np.uint8)
        for colour_range in ranges:
            mask |= cv2.inRange(hsv, np.array(colour_range.lower, np.uint8), np.array(colour_range.upper, np.uint8))
        if kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
        masks[name] = mask > 0
    return masks


# -- geometry -----------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PlaneProjection:
    """A pinhole camera (``fx, fy, cx, cy``; optical frame x right, y down, z forward) at ``pose`` (4x4, robot base
    frame) and the horizontal plane ``z = plane_z`` it looks at. Pixel ``[row, col]`` has centre
    ``(col + 0.5, row + 0.5)``, like :mod:`bt_meta.world.simulation.camera`."""

    fx: float
    fy: float
    cx: float
    cy: float
    pose: np.ndarray
    plane_z: float
    width: int
    height: int

    @classmethod
    def from_image(cls, image: Any, plane_z: float) -> PlaneProjection:
        """For a :class:`~bt_meta.world.simulation.camera.CameraImage` (its intrinsics and the pose it was taken at)."""
        k = image.intrinsics
        return cls(k.fx, k.fy, k.cx, k.cy, np.asarray(image.pose, float), float(plane_z), k.width, k.height)

    @classmethod
    def top_down(
        cls,
        width: int,
        height: int,
        centre: tuple[float, float],
        metres_per_pixel: float,
        *,
        plane_z: float = 0.0,
        camera_height: float = 1.0,
    ) -> PlaneProjection:
        """A camera ``camera_height`` above the plane looking straight down with ``metres_per_pixel`` on the plane,
        oriented like :class:`~bt_meta.world.simulation.camera.TopViewCamera` (image up = +x, image right = -y). For
        drawing
        synthetic images with exact answers."""
        if metres_per_pixel <= 0 or camera_height <= 0:
            raise PerceptionConfigError("a top-down projection needs positive metres per pixel and camera height")
        f = camera_height / metres_per_pixel
        pose = np.eye(4)
        pose[:3, :3] = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
        pose[:3, 3] = [centre[0], centre[1], plane_z + camera_height]
        return cls(f, f, width / 2.0, height / 2.0, pose, plane_z, width, height)

    def at_height(self, plane_z: float) -> PlaneProjection:
        """The same camera onto another horizontal plane (e.g. the blocks' top face)."""
        return PlaneProjection(self.fx, self.fy, self.cx, self.cy, self.pose, float(plane_z), self.width, self.height)

    def pixel_to_table(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the rays through pixels ``(u, v)`` meet the plane: ``(x, y)`` arrays in the base frame."""
        u, v = np.asarray(u, float), np.asarray(v, float)
        rays = np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], axis=-1)
        directions = rays @ self.pose[:3, :3].T
        origin = self.pose[:3, 3]
        if np.any(np.abs(directions[..., 2]) < 1e-12):
            raise PerceptionConfigError("a pixel ray is parallel to the table plane")
        t = (self.plane_z - origin[2]) / directions[..., 2]
        if np.any(t <= 0):
            raise PerceptionConfigError(f"the plane z = {self.plane_z} is behind the camera")
        return origin[0] + t * directions[..., 0], origin[1] + t * directions[..., 1]

    def pixel_to_point(self, u: np.ndarray, v: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Base-frame points (N x 3) of pixels at optical depth ``depth`` (metres along the optical axis)."""
        u, v, d = (np.asarray(a, float) for a in (u, v, depth))
        points = np.stack([(u - self.cx) / self.fx * d, (v - self.cy) / self.fy * d, d], axis=-1)
        return points @ self.pose[:3, :3].T + self.pose[:3, 3]

    def table_to_pixel(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels ``(u, v)`` of plane points ``(x, y)``."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        points = np.stack([x, y, np.full_like(x, self.plane_z)], axis=-1) - self.pose[:3, 3]
        camera = points @ self.pose[:3, :3]  # R^T p, row-wise
        return self.fx * camera[..., 0] / camera[..., 2] + self.cx, self.fy * camera[..., 1] / camera[..., 2] + self.cy


# -- blocks -------------------------------------------------------------------------------------------------------


def classify_shape(length: float, width: float, lb: float = LB) -> str:
    """``"1x1"`` or ``"1x2"`` from a blob's metric axis lengths against ``lb``; ``"unknown"`` for anything else
    (two blocks merged into one blob, a partly hidden block)."""
    if width < 0.5 * lb or width > 1.5 * lb:
        return "unknown"
    if length < 1.5 * lb:
        return "1x1"
    if length < 2.5 * lb:
        return "1x2"
    return "unknown"


@dataclass(frozen=True)
class Block:
    """One detected block. ``centroid`` (x, y) and ``orientation`` (rad) are in the table/base frame;
    ``orientation`` is the long axis' angle from +x, in (-pi/2, pi/2] for a 1x2 and (-pi/4, pi/4] for a 1x1 (a
    square has no long axis). ``length``/``width`` are the metric axis lengths the shape was decided from;
    ``top_z`` the height of the surface measured (the plane's height without depth)."""

    index: int
    colour: str
    shape: str
    centroid: tuple[float, float]
    orientation: float
    length: float
    width: float
    pixels: int
    pixel_centroid: tuple[float, float]
    top_z: float
    bbox: tuple[int, int, int, int] = field(default=(0, 0, 0, 0))
    """Pixel bounding box (col, row, width, height)."""

    @property
    def label(self) -> str:
        """The paper's ``b_i = <colour, shape>``."""
        return f"b{self.index}=<{self.colour}, {self.shape}>"

    def as_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "colour": self.colour,
            "shape": self.shape,
            "centroid": list(self.centroid),
            "orientation": self.orientation,
            "length": self.length,
            "width": self.width,
            "pixels": self.pixels,
            "pixel_centroid": list(self.pixel_centroid),
            "top_z": self.top_z,
        }


def _fold(angle: float, period: float) -> float:
    """``angle`` folded into (-period/2, period/2]."""
    folded = math.fmod(angle + period / 2.0, period)
    if folded <= 0.0:
        folded += period
    return folded - period / 2.0


def _axes(points: np.ndarray) -> tuple[float, float, float]:
    """(length, width, angle of the long axis) of a uniformly filled rectangle's points (N x 2, metres)."""
    centred = points - points.mean(axis=0)
    covariance = centred.T @ centred / max(len(points), 1)
    values, vectors = np.linalg.eigh(covariance)
    major = vectors[:, 1]
    # A uniform rectangle of side L has variance L^2 / 12 along that side.
    return (math.sqrt(12.0 * max(values[1], 0.0)), math.sqrt(12.0 * max(values[0], 0.0)),
            math.atan2(major[1], major[0]))


def _footprint(points: np.ndarray) -> tuple[tuple[float, float], float]:
    """(centre, side angle mod 90 degrees) of the minimum-area rectangle around plan points (N x 2, metres).

    The rectangle's centre, not the points' mean, is the footprint's centroid: seen in perspective, a stud hides
    a strip of the top face behind it and shows its side instead, which moves the mean towards the camera's
    nadir by a millimetre or two, but never the outline (the top face's corners stay in view)."""
    (cx, cy), (_, _), degrees = cv2.minAreaRect((points * 1000.0).astype(np.float32))
    return (cx / 1000.0, cy / 1000.0), _fold(math.radians(degrees), math.pi / 2.0)


def detect_blocks(
    rgb: np.ndarray,
    projection: PlaneProjection,
    *,
    depth: np.ndarray | None = None,
    thresholds: HSVThresholds = DEFAULT_THRESHOLDS,
    lb: float = LB,
    surface_tolerance: float = 0.003,
) -> list[Block]:
    """Every coloured blob of ``rgb`` as a :class:`Block`, ordered by pixel position (top-left first).

    ``depth`` (H x W metres along the optical axis, e.g. :attr:`CameraImage.depth`) switches on the 3-D
    top-surface measurement described in the module docstring; without it pixels go onto ``projection``'s plane.
    """
    image = np.asarray(rgb)
    if projection.width != image.shape[1] or projection.height != image.shape[0]:
        raise ValueError(
            f"image is {image.shape[1]}x{image.shape[0]} but the projection is {projection.width}x{projection.height}"
        )
    if depth is not None and np.asarray(depth).shape != image.shape[:2]:
        raise ValueError(f"depth image shape {np.asarray(depth).shape} does not match the RGB {image.shape[:2]}")
    found: list[tuple[tuple[float, float], Block]] = []
    for colour, mask in colour_masks(image, thresholds).items():
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
        for label in range(1, count):
            area = int(stats[label, cv2.CC_STAT_AREA])
            if area < thresholds.min_pixels:
                continue
            rows, cols = np.nonzero(labels == label)
            u, v = cols + 0.5, rows + 0.5
            if depth is not None:
                points = projection.pixel_to_point(u, v, np.asarray(depth)[rows, cols])
                top = float(np.median(points[:, 2]))
                if top < projection.plane_z - 0.01:
                    continue  # below the table top: the floor or the background beyond the table's edge
                keep = points[:, 2] >= top - surface_tolerance
                plan = points[keep, :2]
            else:
                top = projection.plane_z
                xs, ys = projection.pixel_to_table(u, v)
                plan = np.stack([xs, ys], axis=1)
            length, width, angle = _axes(plan)
            shape = classify_shape(length, width, lb)
            centroid, square_angle = _footprint(plan)
            orientation = square_angle if shape == "1x1" else _fold(angle, math.pi)
            bbox = tuple(int(stats[label, i]) for i in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP,
                                                         cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT))
            pixel_centroid = (float(u.mean()), float(v.mean()))
            block = Block(0, colour, shape, (float(centroid[0]), float(centroid[1])), orientation, length, width,
                          area, pixel_centroid, top, bbox)  # type: ignore[arg-type]
            found.append(((pixel_centroid[1], pixel_centroid[0]), block))
    found = _without_side_faces(found)
    found.sort(key=lambda item: item[0])
    return [_reindex(block, i) for i, (_, block) in enumerate(found)]


def _touching(a: tuple[int, int, int, int], b: tuple[int, int, int, int], margin: int = 2) -> bool:
    return (a[0] - margin < b[0] + b[2] and b[0] - margin < a[0] + a[2]
            and a[1] - margin < b[1] + b[3] and b[1] - margin < a[1] + a[3])


def _without_side_faces(found: list[tuple[tuple[float, float], Block]]) -> list[tuple[tuple[float, float], Block]]:
    """Drop blobs of no block shape that touch a block of another colour: the block's shaded side faces, which
    for a grey render as the next darker grey (a chromatic colour's sides keep its hue and join its blob)."""
    shaped = [block for _, block in found if block.shape != "unknown"]
    return [(key, block) for key, block in found if block.shape != "unknown" or not any(
        other.colour != block.colour and _touching(other.bbox, block.bbox) for other in shaped)]


def _reindex(block: Block, index: int) -> Block:
    return Block(index, block.colour, block.shape, block.centroid, block.orientation, block.length, block.width,
                 block.pixels, block.pixel_centroid, block.top_z, block.bbox)


def nearest_block(blocks: Sequence[Block], point: Sequence[float], radius: float) -> Block | None:
    """The block whose centroid is nearest ``point`` (x, y), if within ``radius`` metres."""
    best, best_distance = None, radius
    for block in blocks:
        distance = math.hypot(block.centroid[0] - point[0], block.centroid[1] - point[1])
        if distance <= best_distance:
            best, best_distance = block, distance
    return best
