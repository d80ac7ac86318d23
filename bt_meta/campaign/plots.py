"""Plots drawn with matplotlib (headless ``Agg``), returned as SVG text to inline in HTML reports.

One place for every report's figures -- the campaign report's and the demo report's -- so labels are laid out by
matplotlib (nothing clipped) and bands are drawn with a visible fill.

Offers:

* :func:`rate_bars` -- grouped bars of rates with interval whiskers (campaign: expected outcome x configuration)
* :func:`heatmap` -- a labelled count matrix (the confusion table)
* :func:`series` -- lines over steps with a shaded min-max band and marked points (the demo's R_p / R_n)
* :func:`horizontal_bars` -- one bar per label (the demo's failure kinds and attempts)
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Any

__all__ = ["heatmap", "horizontal_bars", "rate_bars", "series"]


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _svg(figure: Any) -> str:
    plt = _pyplot()
    buffer = io.StringIO()
    figure.tight_layout()
    figure.savefig(buffer, format="svg", bbox_inches="tight")
    plt.close(figure)
    text = buffer.getvalue()
    return text[text.find("<svg"):]


def rate_bars(groups: Sequence[str], series_names: Sequence[str], rates: dict[tuple[str, str], float],
              intervals: dict[tuple[str, str], tuple[float, float]], *, title: str = "", ylabel: str = "rate") -> str:
    """Bars of ``rates[(group, series)]`` with ``intervals`` as whiskers, groups along x."""
    import numpy as np

    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(max(5.0, 1.6 * len(groups) + 2.0), 3.4))
    width = 0.8 / max(1, len(series_names))
    x = np.arange(len(groups))
    for k, name in enumerate(series_names):
        values = [rates.get((g, name), np.nan) for g in groups]
        low = [v - intervals.get((g, name), (v, v))[0] for g, v in zip(groups, values, strict=True)]
        high = [intervals.get((g, name), (v, v))[1] - v for g, v in zip(groups, values, strict=True)]
        axes.bar(x + (k - (len(series_names) - 1) / 2.0) * width, values, width, label=name,
                 yerr=[low, high], capsize=3)
    axes.set_xticks(x, groups, rotation=15, ha="right")
    axes.set_ylim(0.0, 1.05)
    axes.set_ylabel(ylabel)
    if title:
        axes.set_title(title)
    axes.legend(fontsize="small", ncols=min(4, len(series_names)))
    axes.grid(axis="y", alpha=0.3)
    return _svg(figure)


def heatmap(rows: Sequence[str], columns: Sequence[str], counts: dict[tuple[str, str], int], *,
            title: str = "") -> str:
    import numpy as np

    plt = _pyplot()
    data = np.array([[counts.get((r, c), 0) for c in columns] for r in rows], dtype=float)
    figure, axes = plt.subplots(figsize=(max(4.0, 0.9 * len(columns) + 2.5), max(2.5, 0.5 * len(rows) + 1.5)))
    image = axes.imshow(data, cmap="Blues", aspect="auto")
    axes.set_xticks(range(len(columns)), columns, rotation=30, ha="right")
    axes.set_yticks(range(len(rows)), rows)
    for i in range(len(rows)):
        for j in range(len(columns)):
            axes.text(j, i, f"{int(data[i, j])}", ha="center", va="center",
                      color="white" if data[i, j] > data.max() / 2 else "black")
    if title:
        axes.set_title(title)
    figure.colorbar(image, ax=axes, shrink=0.8)
    return _svg(figure)


def series(x: Sequence[float], lines: dict[str, Sequence[float]], *, band: tuple[Sequence[float], Sequence[float]]
           | None = None, band_label: str = "min-max", marks: Sequence[float] = (), mark_label: str = "",
           xlabel: str = "", ylabel: str = "", title: str = "", xticklabels: Sequence[str] | None = None) -> str:
    """Lines over ``x``; ``band`` (low, high) shaded; ``marks`` x values drawn as vertical red lines."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(6.4, 3.0))
    if band is not None:
        axes.fill_between(x, band[0], band[1], alpha=0.3, color="tab:blue", label=band_label, linewidth=0)
    for name, values in lines.items():
        axes.plot(x, values, marker="o", markersize=3, label=name)
    for k, value in enumerate(marks):
        axes.axvline(value, color="tab:red", linestyle="--", linewidth=1, label=mark_label if k == 0 else None)
    if xticklabels is not None:
        axes.set_xticks(list(x), list(xticklabels), rotation=30, ha="right", fontsize="x-small")
    axes.set_xlabel(xlabel)
    axes.set_ylabel(ylabel)
    if title:
        axes.set_title(title)
    axes.grid(alpha=0.3)
    axes.legend(fontsize="small")
    return _svg(figure)


def horizontal_bars(labels: Sequence[str], values: Sequence[float], *, xlabel: str = "", title: str = "") -> str:
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(6.0, max(1.6, 0.35 * len(labels) + 1.0)))
    axes.barh(range(len(labels)), values, color="tab:orange")
    axes.set_yticks(range(len(labels)), labels)
    axes.invert_yaxis()
    axes.set_xlabel(xlabel)
    if title:
        axes.set_title(title)
    axes.grid(axis="x", alpha=0.3)
    return _svg(figure)
