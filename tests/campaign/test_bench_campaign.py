"""``bt-meta bench campaign``: the same population in every mode, figures per core-hour against the 1-worker pool."""

from __future__ import annotations

import pytest

from bt_meta.cli import main

SPEC = """family: housing
perturbations:
  - shift: {probability: 1.0, objects: [housing], distance: [0.005, 0.01]}
"""


@pytest.mark.slow
def test_the_pool_modes_run_the_same_episodes_and_are_compared_with_one_worker(tmp_path):
    from bt_meta.bench.campaign import run

    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    result = run("housing", n=2, seed=1, spec=str(spec), configuration="retry", nodes=0)
    assert [m["mode"] for m in result["modes"]] == ["pool, 1 worker", "pool, 2 workers"]
    one, two = result["modes"]
    assert result["same_outcomes"] and one["episodes"] == two["episodes"] == 2
    assert one["per_core_vs_pool_1"] == one["speed_up_vs_pool_1"] == 1.0
    assert two["cores"] == 2 and two["episodes_per_core_hour"] == pytest.approx(2 * 3600 / (2 * two["wall_seconds"]))
    assert two["per_core_vs_pool_1"] == pytest.approx(one["wall_seconds"] / (2 * two["wall_seconds"]))


def test_bad_arguments_exit_2(capsys):
    assert main(["bench", "campaign", "--n", "0"]) == 2
    assert "--n must be between 1 and 500" in capsys.readouterr().err
    assert main(["bench", "campaign", "--family", "nope"]) == 2
    assert main(["bench", "campaign", "--ray", "127.0.0.1:9", "--nodes", "0"]) == 2
    assert "no Ray cluster answers there" in capsys.readouterr().err
