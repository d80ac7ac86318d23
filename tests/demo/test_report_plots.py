"""The demo report's R_p / R_n plots are matplotlib's (bt_meta.plotting): failure labels in the legend, the
remembered min-max band filled visibly; the hand-drawn line plot is gone."""

from __future__ import annotations

import re
from types import SimpleNamespace
from xml.etree import ElementTree

from bt_meta.demo import report, svg


def _relation(mean: float) -> dict[str, dict[str, float]]:
    return {"r_p_mm": {"mean": mean, "min": mean - 2.0, "max": mean + 2.0},
            "r_n_deg": {"mean": 10.0 * mean, "min": 10.0 * mean - 5.0, "max": 10.0 * mean + 5.0}}


def test_keypoint_plots_are_drawn_by_matplotlib_with_their_failure_markers():
    observed = [{"step": k, "segment": 1, "status": "SUCCESS" if k != 2 else "FAILURE", "call": f"step {k}",
                 "r_p_mm": 1.0 + k, "r_n_deg": 12.0 * k} for k in range(4)]
    outcome = SimpleNamespace(keypoints={"observed": observed, "expected": {str(k): _relation(1.0 + k)
                                                                            for k in range(4)},
                                         "traces": 3, "active": "peg", "reference": "base"})
    html = report._keypoints(outcome)
    figures = re.findall(r"<svg.*?</svg>", html, re.S)
    assert len(figures) == 2  # R_p and R_n
    for figure in figures:
        ElementTree.fromstring(figure)
        assert "failure step 2" in figure and "min-max" in figure  # the marker's label is in the legend
        assert "fill-opacity: 0.3" in figure  # the band is filled, visibly
    assert not hasattr(svg, "line_plot_svg")
