"""``bt-meta bench groot2`` runs its configurations on a small tree and reports ratios against its baselines."""

from __future__ import annotations

import pytest

from bt_meta.bench.groot2 import run_benchmark, tree_xml
from bt_meta.cli import main

pytestmark = pytest.mark.usefixtures("clean_blackboard")


def test_bench_groot2_reports_every_configuration_against_its_own_baseline() -> None:
    report = run_benchmark(leaves=12, group=4, rounds=2, per_round=1)
    assert report["nodes"] == 1 + 3 * 3 + 12
    rows = report["results"]
    assert set(rows) == {"plain", "observed", "served", "served+btlog", "BT.CPP plain", "BT.CPP served+btlog"}
    assert rows["plain"]["ratio_vs_own_plain"] == 1.0 and rows["BT.CPP plain"]["ratio_vs_own_plain"] == 1.0
    assert all(row["median_ms_per_tick"] > 0 for row in rows.values())


def test_bench_tree_has_the_requested_shape() -> None:
    xml = tree_xml(5, 2)
    assert xml.count("<AlwaysSuccess") == 5 and xml.count("<Inverter>") == 6


def test_bench_groot2_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "groot2", "--leaves", "6", "--group", "3", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    assert "served+btlog" in out and "ratio" in out
