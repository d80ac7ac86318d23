"""``bt-meta bench episode``: the fresh-process and worker figures next to raw pybullet, and its input errors."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main


def test_bad_arguments_exit_2(capsys):
    assert main(["bench", "episode", "--repeat", "0"]) == 2
    assert "--repeat must be between 1 and 50" in capsys.readouterr().err
    assert main(["bench", "episode", "--configuration", "nope"]) == 2
    assert "unknown configuration 'nope'" in capsys.readouterr().err


@pytest.mark.slow
def test_the_bench_reports_both_ways_of_running_an_episode(capsys):
    assert main(["bench", "episode", "--family", "housing", "--repeat", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["real_time_factor"] > 0 and out["worker_real_time_factor"] > 0 and out["pybullet_real_time_factor"] > 0
    (fresh,) = out["runs"]
    # each ratio is paired with the raw stepping its own process measured right after its episode
    assert out["ratio_to_pybullet"] == pytest.approx(fresh["real_time_factor"] / fresh["raw"]["real_time_factor"])
    assert out["worker_ratio_to_pybullet"] == pytest.approx(out["worker_runs"][0]["ratio_to_pybullet"])
    assert out["cpu_ratio_to_pybullet"] > 0 and out["worker_cpu_ratio_to_pybullet"] > 0
    worker = out["worker"]
    assert worker["episodes"] == 1 and worker["same_outcomes_as_fresh"] is True
    assert worker["warm_up"]["phases"]["import"] > 0  # the warm-up carries the imports, the timed episodes do not
    assert "import" not in out["worker_runs"][0]["phases"]
    assert fresh["process_wall_seconds"] > fresh["phases"]["episode"] > fresh["phases"]["run"] > 0
    assert fresh["simulated_seconds"] == out["worker_runs"][0]["simulated_seconds"] > 0
