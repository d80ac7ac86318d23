"""HSV thresholds derived from declared colours: perception sees every colour a scene file may name.

The scene format accepts the colours of :data:`bt_meta.world.simulation.objects.COLOURS`; the paper's red and
blue were the only ones hand-tuned. Here each declared RGB colour gets its HSV box:

* a **chromatic** colour (saturation >= :data:`CHROMA_S`) by hue, halfway to the nearest other chromatic colour's
  hue (at most :data:`MAX_HUE_HALF_WIDTH`), saturated at least half its own saturation and bright at least
  :data:`MIN_V_FRACTION` of its value -- shading scales value, not hue or saturation;
* an **achromatic** one (white, greys, black) by value, halfway to the neighbouring greys, with a saturation
  at most halfway to the background's (the beige table), so the table itself is never a block; chromatic
  colours then start above every grey's saturation. Darker, the bound is a chroma (max - min channel) rather
  than a saturation: pixel noise of a few DN is a large saturation on a black pixel, so the saturation bound
  grows as the value falls, up to the chromatic colours' floor.

Offers:

* :func:`thresholds_for` -- :class:`~bt_meta.perception.hsv.HSVThresholds` for a mapping of colour name -> RGB(A)
* :func:`scene_thresholds` -- those of every colour the scene format defines, on a given background
* :func:`hsv_of` -- an RGB(A) colour (0..1 floats) in OpenCV HSV (H 0..179, S and V 0..255)
* :func:`balance_to_background` -- an image whose lighting (brightness, white balance) changed, corrected so the
  background (the table, most of a top view) shows its declared colour again: the greys, told by value, are then
  seen under a dimmer or warmer light too (a chromatic colour's hue does not need it)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from functools import lru_cache

import cv2
import numpy as np

from bt_meta.perception.hsv import ColourRange, HSVThresholds, PerceptionConfigError

__all__ = ["CHROMA_S", "MAX_HUE_HALF_WIDTH", "MIN_V_FRACTION", "balance_to_background", "hsv_of", "scene_thresholds",
           "thresholds_for"]

CHROMA_S = 90
"""OpenCV saturation from which a colour is told by its hue (below: by its value)."""
MAX_HUE_HALF_WIDTH = 10
MIN_V_FRACTION = 0.3
ACHROMATIC_MAX_S = 40
"""The highest saturation an achromatic colour may show (lower still on a background more saturated than this)."""
GREY_CHROMA_NOISE = 12.0
"""DN of chroma (max - min channel) pixel noise may add to a grey: 2.5 DN of noise per channel, about 5 sigma."""
GREY_BAND = 16
"""Width (V) of the sub-bands an achromatic colour's saturation bound is stepped over."""
BACKGROUND_BAND = 0.15
"""Pixels within this fraction (per channel) of the image's median are the background a lighting gain is read from."""
MAX_GAIN = 2.0
"""A lighting correction never scales a channel by more than this (or less than its inverse): an image that is not
mostly background is left nearly as it is."""


def hsv_of(rgb: Sequence[float]) -> tuple[int, int, int]:
    """``rgb`` (three or four floats in 0..1) as OpenCV HSV integers."""
    values = [float(v) for v in list(rgb)[:3]]
    if len(values) != 3 or not all(0.0 <= v <= 1.0 for v in values):
        raise PerceptionConfigError(f"a colour must be 3 (or 4) numbers in 0..1, got {list(rgb)!r}")
    pixel = np.array([[[round(v * 255) for v in values]]], np.uint8)
    h, s, v = (int(c) for c in cv2.cvtColor(pixel, cv2.COLOR_RGB2HSV)[0, 0])
    return h, s, v


def _hue_distance(a: int, b: int) -> int:
    d = abs(a - b) % 180
    return min(d, 180 - d)


def _hue_ranges(centre: int, half: int, s_low: int, v_low: int) -> tuple[ColourRange, ...]:
    low, high = centre - half, centre + half
    if low < 0:
        return (ColourRange((0, s_low, v_low), (high, 255, 255)),
                ColourRange((180 + low, s_low, v_low), (179, 255, 255)))
    if high > 179:
        return (ColourRange((low, s_low, v_low), (179, 255, 255)),
                ColourRange((0, s_low, v_low), (high - 180, 255, 255)))
    return (ColourRange((low, s_low, v_low), (high, 255, 255)),)


def thresholds_for(colours: Mapping[str, Sequence[float]], background: Sequence[float] | None = None, *,
                   min_pixels: int = 20, open_kernel: int = 3) -> HSVThresholds:
    """HSV thresholds telling ``colours`` (name -> RGB(A) in 0..1) apart, in their order, on ``background``."""
    if not colours:
        raise PerceptionConfigError("thresholds_for needs at least one colour")
    hsv = {name: hsv_of(rgb) for name, rgb in colours.items()}
    chromatic = {n: c for n, c in hsv.items() if c[1] >= CHROMA_S}
    achromatic = {n: c for n, c in hsv.items() if c[1] < CHROMA_S}
    background_s = None if background is None else hsv_of(background)[1]

    def grey_max_s(own: int) -> int:  # halfway between the grey's saturation and the background's
        if background_s is None or background_s <= own:
            return max(own, ACHROMATIC_MAX_S) if background_s is None else own
        return max(own, min(ACHROMATIC_MAX_S, (own + background_s) // 2))

    max_s = max([grey_max_s(c[1]) for c in achromatic.values()] or [grey_max_s(0)])
    ranges: dict[str, tuple[ColourRange, ...]] = {}
    for name, (h, s, v) in chromatic.items():
        others = {n: _hue_distance(h, o[0]) for n, o in chromatic.items() if n != name}
        same = sorted(n for n, d in others.items() if d == 0)
        if same:
            raise PerceptionConfigError(f"colours {name!r} and {same[0]!r} have the same hue: not told apart")
        half = min([MAX_HUE_HALF_WIDTH, *((d - 1) // 2 for d in others.values())])
        ranges[name] = _hue_ranges(h, half, max(max_s + 1, s // 2), max(1, int(MIN_V_FRACTION * v)))
    chroma_floor = min([r[0].lower[1] for r in ranges.values()] or [CHROMA_S])
    chroma_v = min([r[0].lower[2] for r in ranges.values()] or [256])
    greys = sorted(achromatic.items(), key=lambda item: item[1][2])
    for index, (name, (_, own_s, v)) in enumerate(greys):
        below = greys[index - 1][1][2] if index > 0 else None
        above = greys[index + 1][1][2] if index + 1 < len(greys) else None
        low = 0 if below is None else (below + v) // 2 + 1
        high = 255 if above is None else (v + above) // 2
        if low > high:
            raise PerceptionConfigError(f"colours {name!r} and {greys[index - 1][0]!r} have the same value: not "
                                        "told apart")
        ranges[name] = _grey_ranges(low, high, grey_max_s(own_s), own_s * v / 255.0, chroma_floor - 1, chroma_v)
    return HSVThresholds({name: ranges[name] for name in colours}, min_pixels, open_kernel)


def _grey_ranges(low: int, high: int, max_s: int, chroma: float, ceiling: int, ceiling_from: int
                 ) -> tuple[ColourRange, ...]:
    """An achromatic colour's value band ``low..high``, cut into sub-bands whose saturation bound grows as the value
    falls: a grey is a small chroma (max - min channel, in DN) -- its own plus :data:`GREY_CHROMA_NOISE` -- and the
    same chroma is a larger HSV saturation on a darker pixel. Never below ``max_s`` (the bound at full value), nor
    above ``ceiling`` (the chromatic colours' saturation floor) where a chromatic colour may show (value >=
    ``ceiling_from``)."""
    out = []
    start = low
    while start <= high:
        end = min(high, start + GREY_BAND - 1)
        bound = 255 if start == 0 else min(255, math.ceil(255.0 * (chroma + GREY_CHROMA_NOISE) / start))
        if end >= ceiling_from:
            bound = min(ceiling, bound)
        out.append(ColourRange((0, 0, start), (179, int(max(max_s, bound)), end)))
        start = end + 1
    return tuple(out)


@lru_cache(maxsize=8)
def _scene_thresholds(background: tuple[float, ...] | None) -> HSVThresholds:
    from bt_meta.world.simulation.objects import COLOURS

    ordered = {"red": COLOURS["red"], "blue": COLOURS["blue"]}  # the paper's colours keep grid-map codes 1 and 2
    ordered.update({name: rgba for name, rgba in COLOURS.items() if name not in ordered})
    return thresholds_for(ordered, background)


def scene_thresholds(background: Sequence[float] | None = None) -> HSVThresholds:
    """Thresholds for every colour the scene format accepts (red and blue first), on ``background`` (RGB(A))."""
    return _scene_thresholds(None if background is None else tuple(float(v) for v in background))


def balance_to_background(rgb: np.ndarray, background: Sequence[float]) -> np.ndarray:
    """``rgb`` (H x W x 3 uint8) with a per-channel gain applied so its background shows ``background`` (RGB(A) in
    0..1) again.

    The background is read as the pixels near the image's median colour (a top view is mostly table); its median
    per channel against the declared colour is the gain the lighting applied, undone here. Values clip at 255: an
    over-exposed frame that clipped the background loses what told it from a white block, and no gain gives it back.
    """
    image = np.asarray(rgb)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an H x W x 3 uint8 RGB image, got {image.dtype} {image.shape}")
    pixels = image.reshape(-1, 3).astype(np.float32)
    median = np.median(pixels, axis=0)
    near = np.all(np.abs(pixels - median) <= BACKGROUND_BAND * np.maximum(median, 1.0), axis=1)
    seen = np.median(pixels[near], axis=0) if np.any(near) else median
    wanted = np.array([float(v) for v in list(background)[:3]], np.float32) * 255.0
    gain = np.clip(wanted / np.maximum(seen, 1.0), 1.0 / MAX_GAIN, MAX_GAIN)
    return np.clip(np.rint(image.astype(np.float32) * gain), 0, 255).astype(np.uint8)

