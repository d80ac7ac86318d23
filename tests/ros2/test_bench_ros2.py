"""``bt-meta bench ros2`` runs end to end (slow: it serves the simulator twice), and bad arguments exit 2 before
anything starts. No timing is asserted: the figures are in docs/benchmarks.md."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bt_meta.cli import main

from .conftest import REASON

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(("argv", "message"), [
    (["--ticks", "3"], "--ticks must be between 10 and 5000"),
    (["--repeat", "0"], "--repeat must be between 1 and 10"),
    (["--problem", "no_such_problem"], "no_such_problem"),
])
def test_bad_arguments_exit_2(capsys, argv, message):
    assert main(["bench", "ros2", *argv]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.skipif(REASON is not None, reason=REASON or "")
def test_the_benchmark_runs_and_reports_both_ways():
    done = subprocess.run([sys.executable, "-m", "bt_meta.cli", "bench", "ros2", "--ticks", "10", "--json"], cwd=ROOT,
                          capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout)
    tick, episode = result["tick"], result["episode"]
    assert tick["in_process_ms"] > 0 and tick["ros2_ms"] > 0 and tick["ratio"] > 0
    assert [r["status"] for r in episode["in_process"]] == [r["status"] for r in episode["ros2"]] == ["SUCCESS"]
    assert episode["in_process"][0]["ticks"] == episode["ros2"][0]["ticks"]
