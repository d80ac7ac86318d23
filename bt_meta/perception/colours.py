"""HSV thresholds derived from declared colours: perception sees every colour a scene file may name.

The scene format accepts the colours of :data:`bt_meta.world.simulation.objects.COLOURS`; the paper's red and
blue were the only ones hand-tuned. Here each declared RGB colour gets its HSV box:

* a **chromatic** colour (saturation >= :data:`CHROMA_S`) by hue, halfway to the nearest other chromatic colour's
  hue (at most :data:`MAX_HUE_HALF_WIDTH`), saturated at least half its own saturation and bright at least
  :data:`MIN_V_FRACTION` of its value -- shading scales value, not hue or saturation;
* an **achromatic** one (white, greys, black) by value, halfway to the neighbouring greys, with a saturation
  at most halfway to the background's (the beige table), so the table itself is never a block; chromatic
  colours then start above every grey's saturation.

Offers:

* :func:`thresholds_for` -- :class:`~bt_meta.perception.hsv.HSVThresholds` for a mapping of colour name -> RGB(A)
* :func:`scene_thresholds` -- those of every colour the scene format defines, on a given background
* :func:`hsv_of` -- an RGB(A) colour (0..1 floats) in OpenCV HSV (H 0..179, S and V 0..255)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache

import cv2
import numpy as np

from bt_meta.perception.hsv import ColourRange, HSVThresholds, PerceptionConfigError

__all__ = ["CHROMA_S", "MAX_HUE_HALF_WIDTH", "MIN_V_FRACTION", "hsv_of", "scene_thresholds", "thresholds_for"]

CHROMA_S = 90
"""OpenCV saturation from which a colour is told by its hue (below: by its value)."""
MAX_HUE_HALF_WIDTH = 10
MIN_V_FRACTION = 0.3
ACHROMATIC_MAX_S = 40
"""The highest saturation an achromatic colour may show (lower still on a background more saturated than this)."""


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
    greys = sorted(achromatic.items(), key=lambda item: item[1][2])
    for index, (name, (_, own_s, v)) in enumerate(greys):
        below = greys[index - 1][1][2] if index > 0 else None
        above = greys[index + 1][1][2] if index + 1 < len(greys) else None
        low = 0 if below is None else (below + v) // 2 + 1
        high = 255 if above is None else (v + above) // 2
        if low > high:
            raise PerceptionConfigError(f"colours {name!r} and {greys[index - 1][0]!r} have the same value: not "
                                        "told apart")
        ranges[name] = (ColourRange((0, 0, low), (179, grey_max_s(own_s), high)),)
    return HSVThresholds({name: ranges[name] for name in colours}, min_pixels, open_kernel)


@lru_cache(maxsize=8)
def _scene_thresholds(background: tuple[float, ...] | None) -> HSVThresholds:
    from bt_meta.world.simulation.objects import COLOURS

    ordered = {"red": COLOURS["red"], "blue": COLOURS["blue"]}  # the paper's colours keep grid-map codes 1 and 2
    ordered.update({name: rgba for name, rgba in COLOURS.items() if name not in ordered})
    return thresholds_for(ordered, background)


def scene_thresholds(background: Sequence[float] | None = None) -> HSVThresholds:
    """Thresholds for every colour the scene format accepts (red and blue first), on ``background`` (RGB(A))."""
    return _scene_thresholds(None if background is None else tuple(float(v) for v in background))
