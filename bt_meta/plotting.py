"""Plots drawn with matplotlib (headless ``Agg``), returned as SVG text to inline in HTML reports.

One place for every report's figures -- the campaign report's and the demo report's -- so labels are laid out by
matplotlib (nothing clipped) and bands are drawn with a visible fill.

Offers:

* :func:`rate_bars` -- grouped bars of rates with interval whiskers (campaign: expected outcome x configuration)
* :func:`heatmap` -- a labelled count matrix (the confusion table)
* :func:`line_plot` -- series of (x, y) points (``None`` breaks a line), shaded bands (x, low, high) per series,
  vertical markers (x, label) listed in the legend: the demo report's R_p / R_n over the executed steps
* :func:`horizontal_bars` -- one bar per label
"""

from __future__ import annotations

import html
import io
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["heatmap", "horizontal_bars", "line_plot", "rate_bars"]


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


def line_plot(series: Mapping[str, Sequence[tuple[float, float | None]]], *, title: str, x_label: str,
              y_label: str, bands: Mapping[str, Sequence[tuple[float, float, float]]] | None = None,
              markers: Sequence[tuple[float, str]] = (), width: float = 5.2, height: float = 3.2) -> str:
    """Lines with optional bands (drawn at 30 % opacity with an edge, so a narrow band stays visible) and dashed
    vertical markers whose labels go in the legend (nothing is clipped at the plot's edge)."""
    import math

    bands = bands or {}
    if not any(y is not None for values in series.values() for _, y in values) and not any(bands.values()):
        return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{int(width * 90)}" height="40"><text x="4" y="20" '
                f'font-family="sans-serif" font-size="12">{html.escape(title)}: no data</text></svg>')
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(width, height))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for index, (name, values) in enumerate(series.items()):
        colour = colours[index % len(colours)]
        band = bands.get(name)
        if band:
            xs = [b[0] for b in band]
            axes.fill_between(xs, [b[1] for b in band], [b[2] for b in band], color=colour, alpha=0.3,
                              edgecolor=colour, linewidth=0.8, label=f"{name}: min-max")
        xs = [float(x) for x, _ in values]
        ys = [math.nan if y is None else float(y) for _, y in values]
        axes.plot(xs, ys, marker="o", markersize=3.5, color=colour, label=name)
    for k, (x, label) in enumerate(markers):
        axes.axvline(x, color="tab:red", linestyle="--", linewidth=1.2,
                     label=label if label not in [m[1] for m in markers[:k]] else None)
    axes.set_title(title, fontsize="medium")
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_label)
    axes.grid(alpha=0.3)
    axes.legend(fontsize="x-small", loc="upper center", bbox_to_anchor=(0.5, -0.22), ncols=2, frameon=False)
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
