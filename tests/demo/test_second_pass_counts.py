"""The demo's totals count a run as a success only when the simulator's ground truth agrees: a run that reports
success on parts that are not joined is a false success, not a second-pass success."""

from __future__ import annotations

from pathlib import Path

from bt_meta.demo.runner import DemoResult, VariantOutcome
from bt_meta.demo.scenario import VariantRun


def _outcome(pass_number: int, achieved: bool | None, attempts: int = 0) -> VariantOutcome:
    run = VariantRun("magnetic", "magnetic_attach.yaml", "nominal", "active_on_side", 0)
    report = {"status": "success", "attempts": [{"number": n + 1} for n in range(attempts)]}
    return VariantOutcome(run, pass_number, report=report, achieved=achieved)


def test_a_second_pass_the_simulator_contradicts_is_not_counted_as_a_success() -> None:
    result = DemoResult(Path("/tmp/unused"), seed=0, quick=True, fresh_memory=True)
    result.runs = [_outcome(1, True, attempts=1), _outcome(2, False, attempts=1), _outcome(2, True),
                   _outcome(2, None)]
    totals = result.summary()["totals"]
    assert totals["second_pass_success"] == 2  # the truth-contradicted run is not one; unknown truth is not a "no"
    assert totals["second_pass_zero_attempts"] == 2
    assert totals["false_successes"] == 1
