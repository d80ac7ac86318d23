"""``bt-meta bench perception``: seeded scenes, the figures it reports, and its input errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bt_meta.bench.perception import random_scene
from bt_meta.cli import main
from bt_meta.errors import UserInputError


def test_random_scenes_are_seeded_inside_the_view_and_clear_of_each_other():
    bounds = ((0.43, 0.97), (-0.57, 0.17))
    first = random_scene(np.random.default_rng(4), 6, bounds)
    assert first == random_scene(np.random.default_rng(4), 6, bounds)
    for i, (_, _, x, y, _) in enumerate(first):
        assert bounds[0][0] < x < bounds[0][1] and bounds[1][0] < y < bounds[1][1]
        for _, _, x2, y2, _ in first[i + 1:]:
            assert math.hypot(x - x2, y - y2) > 0.061
    with pytest.raises(UserInputError, match="use fewer --blocks"):
        random_scene(np.random.default_rng(0), 30, ((0.0, 0.2), (0.0, 0.2)))


def test_bad_arguments_exit_2(capsys):
    assert main(["bench", "perception", "--blocks", "0"]) == 2
    assert "--blocks between 1 and 20" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_reports_accuracy_and_a_ratio(capsys):
    assert main(["bench", "perception", "--n", "2", "--blocks", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for mode in ("depth", "rgb_only"):
        figures = out[mode]
        assert figures["blocks"] == 8 and figures["found"] == 8
        assert figures["shape_accuracy"] == 1.0 and figures["colour_accuracy"] == 1.0
        assert figures["centroid_error_mm"]["p95"] < 8.0
        assert figures["ratio_analysis_vs_ground_truth"] > 0
    assert out["baseline"]["ms_per_frame"] > 0
