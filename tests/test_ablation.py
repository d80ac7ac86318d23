"""``bt-meta experiment ablation``: the interval statistics, the option errors, and a tiny real run.

The tiny run checks the one outcome that holds whatever the repair plugins do: with symbolic expectations only,
A's bar drawn by a single red 1x1 block ends "success" for the executor while the simulator shows holes in the
letter (a false success), and the retry baseline cannot draw the bar with two 1x1 blocks.
"""

from __future__ import annotations

import math

import pytest

from bt_meta.cli import main
from bt_meta.experiments.ablation import bootstrap_mean, run, wilson


def test_wilson_interval_known_values():
    low, high = wilson(5, 10)
    assert low == pytest.approx(0.2366, abs=1e-4) and high == pytest.approx(0.7634, abs=1e-4)
    low, high = wilson(0, 10)
    assert low == pytest.approx(0.0, abs=1e-12) and high == pytest.approx(0.2775, abs=1e-4)
    assert wilson(10, 10)[1] == pytest.approx(1.0) and wilson(0, 0) == (0.0, 1.0)


def test_bootstrap_is_seeded_and_brackets_the_mean():
    values = [0, 1, 1, 2, 5, 3, 1, 0]
    first, second = bootstrap_mean(values, seed=3), bootstrap_mean(values, seed=3)
    assert first == second
    mean, low, high = first
    assert mean == pytest.approx(13 / 8) and low < mean < high
    assert bootstrap_mean([2.0, 2.0]) == (2.0, 2.0, 2.0)
    assert all(math.isnan(v) for v in bootstrap_mean([]))


@pytest.mark.parametrize(("argv", "message"), [
    (["--seeds", "0"], "--seeds must be between 1 and 50"),
    (["--families", "letters,boats"], "--families: unknown boats; known: letters, magnetic, housing"),
    (["--configurations", "dual,magic"], "--configurations: unknown magic"),
    (["--families", "housing", "--variants", "active_on_side"], "--variants: unknown active_on_side"),
])
def test_bad_options_are_input_errors(argv, message, capsys):
    assert main(["experiment", "ablation", *argv]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_symbolic_only_misses_the_substituted_bar():
    result = run(seeds=1, families=("letters",), configurations=("symbolic", "retry"),
                 only=("A_two_1x1_same_colour",))
    assert not result["crashed"]
    runs = {entry["configuration"]: entry for entry in result["runs"]}
    assert set(runs) == {"symbolic", "retry"}
    symbolic = runs["symbolic"]
    assert symbolic["status"] == "success" and symbolic["achieved"] is False and not symbolic["success"]
    assert "not covered" in symbolic["truth"]
    assert runs["retry"]["achieved"] is False and not runs["retry"]["success"]
    rows = {(row["configuration"], row["family"]): row for row in result["rows"]}
    assert set(rows) == {("symbolic", "letters"), ("symbolic", "all"), ("retry", "letters"), ("retry", "all")}
    assert rows["symbolic", "letters"]["false_successes"] == 1 and rows["symbolic", "letters"]["rate"] == 0.0
    assert rows["retry", "letters"]["rate_ci"] == list(wilson(0, 1))
