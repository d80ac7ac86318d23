"""``bt-meta bench guard``: the outcome guard's population gives its recorded outcomes, and a change fails it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from bt_meta.bench.guard import differences, load_baseline, load_population
from bt_meta.cli import main

POPULATION = Path(__file__).resolve().parents[1] / "data" / "guard"
"""The population beside these tests (CI installs bt-meta as a wheel, which carries no tests/)."""

# One or two per family and outcome: a nominal success, a substitution, a pose repair, a reorientation, the
# reachability and collision limits (letters_H is left to the whole population: its memory takes longest to record).
SUBSET = ("letters_A_30_0007", "letters_A_30_0008", "letters_A_30_0004", "magnetic_30_0005", "magnetic_30_0003",
          "housing_30_0008", "housing_30_0004")


def _only(names):
    return [arg for name in names for arg in ("--only", name)]


def test_the_population_and_its_baseline_cover_every_family():
    population = load_population(POPULATION)
    baseline = load_baseline(POPULATION)
    assert len(population["variants"]) >= 40
    assert {v["family"] for v in population["variants"]} == {"letters_A", "letters_H", "magnetic", "housing"}
    assert set(baseline) == {f"{v['family']}/{v['name']}" for v in population["variants"]}
    statuses = {o["status"] for o in baseline.values()}
    assert {"success", "failed"} <= statuses
    assert any(o["attempts"] > 0 for o in baseline.values())


def test_differences_name_each_changed_field_and_note_simulated_time():
    before = {"f/v": {"status": "success", "success": True, "achieved": True, "kinds": ["collision"], "attempts": 1,
                      "repairs": ["pose_backtracking"], "second_exposure": {"status": "success", "attempts": 0},
                      "simulated_seconds": 12.0}}
    same = json.loads(json.dumps(before))
    assert differences(before, same) == ([], [])
    after = json.loads(json.dumps(before))
    after["f/v"].update(kinds=["reachability"], attempts=2, simulated_seconds=13.5)
    failing, noted = differences(before, after)
    assert failing == ["f/v: kinds ['collision'] -> ['reachability']", "f/v: attempts 1 -> 2"]
    assert noted == ["f/v: simulated_seconds 12.0 -> 13.5"]
    assert differences({}, same)[0] == ["f/v: not in the baseline (re-record it with --update)"]


def test_bad_arguments_exit_2(capsys, tmp_path):
    assert main(["bench", "guard", "--population", str(POPULATION), "--only", "no_such_variant"]) == 2
    assert "--only 'no_such_variant': no such variant" in capsys.readouterr().err
    assert main(["bench", "guard", "--population", str(POPULATION), "--update", "--only", SUBSET[0]]) == 2
    assert main(["bench", "guard", "--population", str(tmp_path)]) == 2
    assert "population.json" in capsys.readouterr().err


@pytest.mark.slow
def test_a_subset_of_the_population_keeps_its_recorded_outcomes(capsys):
    code = main(["bench", "guard", "--population", str(POPULATION), *_only(SUBSET), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["failing"] == [], out["failing"]
    assert code == 0 and out["variants"] == len(SUBSET)


@pytest.mark.slow
def test_a_changed_outcome_fails_the_guard_and_update_records_it(capsys, tmp_path):
    folder = tmp_path / "guard"
    shutil.copytree(POPULATION, folder)
    population = json.loads((folder / "population.json").read_text())
    population["variants"] = [v for v in population["variants"] if v["name"] == "magnetic_30_0007"]
    (folder / "population.json").write_text(json.dumps(population))
    baseline = json.loads((folder / "baseline.json").read_text())
    baseline["outcomes"] = {"magnetic/magnetic_30_0007": {**baseline["outcomes"]["magnetic/magnetic_30_0007"],
                                                          "attempts": 3, "kinds": ["collision"]}}
    (folder / "baseline.json").write_text(json.dumps(baseline))
    assert main(["bench", "guard", "--population", str(folder)]) == 1
    out = capsys.readouterr().out
    assert "CHANGED magnetic/magnetic_30_0007: kinds ['collision'] -> ['reachability']" in out
    assert "CHANGED magnetic/magnetic_30_0007: attempts 3 -> 0" in out
    assert main(["bench", "guard", "--population", str(folder), "--update"]) == 0
    assert main(["bench", "guard", "--population", str(folder)]) == 0
    assert "0 changed outcome(s)" in capsys.readouterr().out


@pytest.mark.guard
@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_the_whole_population_keeps_its_recorded_outcomes(capsys):
    """Skipped unless ``-m guard`` (tests/conftest.py): 40 variants take minutes."""
    code = main(["bench", "guard", "--population", str(POPULATION), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["failing"] == [], out["failing"]
    assert code == 0 and out["variants"] >= 40
