"""``bt-meta run``: the task files run headless in the simulator; JSON outcome, tick log, exit statuses."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main
from bt_meta.resources import trees_dir


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["run", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.slow
def test_letter_a_runs_to_success_with_the_blocks_in_place(capsys):
    code, out, _ = run_cli(capsys, str(trees_dir() / "letters.yaml"), "--problem", "A", "--json")
    result = json.loads(out)
    assert code == 0 and result["status"] == "SUCCESS" and result["failures"] == []
    assert result["ticks"] > 6 and len(result["plan"]) == 6
    for line in result["plan"]:
        _, block, x, y = line.split()
        assert ["at", block, x, y] in result["symbolic_state"]
        assert result["objects"][block]["held_by"] is None


@pytest.mark.slow
def test_json_outcome_of_a_failed_run(capsys):
    code, out, _ = run_cli(capsys, str(trees_dir() / "housing_insertion.yaml"), "--problem", "nominal",
                           "--variant", "housing_upside_down", "--json")
    result = json.loads(out)
    assert code == 1 and result["status"] == "FAILURE" and result["variant"] == "housing_upside_down"
    (failure,) = result["failures"]
    assert set(failure) == {"kind", "step", "node_id", "action", "args", "evidence", "message"}
    assert failure["kind"] == "unexpected_configuration" and failure["action"] == "Insert"
    assert failure["evidence"]["distance"] > 0.03
    assert set(result["objects"]) == {"board", "housing"}
    assert result["objects"]["housing"]["held_by"] == "right"


@pytest.mark.slow
def test_tick_log_and_success(capsys):
    code, out, _ = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith("nominal in scene magnetic_attach (nominal), seed 0: 13 primitives planned")
    assert any("MoveTo(staging)=SUCCESS" in line for line in lines)
    assert "SUCCESS after" in out and "joined to active" in out


@pytest.mark.slow
def test_no_plan_is_a_precondition_failure(capsys):
    code, out, _ = run_cli(capsys, str(trees_dir() / "housing_insertion.yaml"), "--problem", "upside_down", "--json")
    result = json.loads(out)
    assert code == 1 and result["status"] == "FAILURE" and result["ticks"] == 0
    assert result["failures"][0]["kind"] == "precondition" and "no plan" in result["failures"][0]["message"]


def test_unknown_problem_lists_the_known_ones(capsys):
    code, out, err = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nope")
    assert code == 2 and out == ""
    assert "no problem named 'nope'; problems: nominal, attach_only" in err


def test_unknown_variant_lists_the_known_ones(capsys):
    code, _, err = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal",
                           "--variant", "sideways")
    assert code == 2
    assert "has no variant 'sideways'; variants: nominal, active_on_side, active_upside_down" in err


def test_bad_max_ticks(capsys):
    code, _, err = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--max-ticks", "0")
    assert code == 2 and "--max-ticks must be at least 1" in err
