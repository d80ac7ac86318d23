"""``bt-meta experiment keypoints``: Tables 2 and 3 from the simulator, and the command's input errors."""

from __future__ import annotations

import json
import math

import pytest

from bt_meta.cli import main
from bt_meta.experiments.keypoints import run, side_magnet_part


def test_object_2_has_its_attachment_normal_on_another_axis():
    model = side_magnet_part()
    assert model.feature().normal == (-1.0, 0.0, 0.0) and model.role == "active"


def test_bad_trace_count_is_an_input_error(capsys):
    assert main(["experiment", "keypoints", "--traces", "0"]) == 2
    assert "--traces must be between 1 and 20" in capsys.readouterr().err


def test_experiment_without_a_name_prints_help(capsys):
    assert main(["experiment"]) == 2
    assert "keypoints" in capsys.readouterr().out


@pytest.mark.slow
def test_tables_2_and_3_separate_nominal_from_failing():
    result = run(traces=2, seed=0)
    assert all(case["attached"] for case in result["nominal"])
    assert result["expectation"]["end"]["r_n"] == pytest.approx(math.pi, abs=0.02)
    on_side, upside_down = result["table2"]
    assert not on_side["attached"] and not upside_down["attached"]
    assert on_side["end"]["r_n"] == pytest.approx(math.pi / 2, abs=0.05)
    assert upside_down["end"]["r_n"] == pytest.approx(0.0, abs=0.05)
    # after the attach motion both relations separate; before any motion only R_n does (R_p of the upside-down
    # part is the nominal distance: the paper's "R_n is more sensitive to gross variations in pose")
    assert result["separates"]["table2"] == {"start": {"p": False, "n": True}, "end": {"p": True, "n": True}}
    nominal2, flat2 = result["table3"]
    assert nominal2["attached"] and not flat2["attached"]
    assert nominal2["judged"]["end"]["n_ok"] and not flat2["judged"]["end"]["n_ok"]
    assert result["separates"]["table3"]["end"]["n"] and result["separates"]["table3"]["start"]["n"]


@pytest.mark.slow
def test_command_prints_json(capsys):
    assert main(["experiment", "keypoints", "--traces", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"expectation", "table2", "table3", "separates", "method"}
    assert [c["label"] for c in out["table3"]] == ["object 2, nominal (magnet down)",
                                                    "object 2, lying flat (magnet sideways)"]
