"""The campaign's numbers: Wilson intervals from scipy, what counts as reaching an expected outcome, the summary."""

from __future__ import annotations

import pytest

from bt_meta.campaign.ablation import verdicts
from bt_meta.campaign.stats import correct, perturbation_classes, pool_classes, summarise, wilson_interval
from bt_meta.experiments.ablation import wilson


def test_bootstrap_interval_is_seeded_and_brackets_the_mean():
    from bt_meta.campaign.stats import _mean

    values = [1.0, 2.0, 2.0, 3.0, 7.0]
    a, b = _mean(values, seed=3), _mean(values, seed=3)
    assert a == b and a["low"] < a["mean"] == 3.0 < a["high"]
    assert _mean([2.0, 2.0]) == {"mean": 2.0, "low": 2.0, "high": 2.0}


def test_wilson_interval_agrees_with_the_closed_form():
    for k, n in ((0, 10), (3, 10), (10, 10), (47, 120)):
        assert wilson_interval(k, n) == pytest.approx(wilson(k, n), abs=1e-9)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def _row(expected, status="failed", kinds=(), configuration="dual", success=None, **more):
    row = {"variant": f"v{len(kinds)}{status}", "configuration": configuration, "seed": 0, "expected": expected,
           "status": status, "success": status == "success" if success is None else success, "attempts": 1,
           "kinds": list(kinds), "seconds": 2.0, "loop": False, "second_exposure": None}
    row.update(more)
    return row


def test_what_reaching_an_expected_outcome_means():
    assert correct(_row("repairable", "success"))
    assert not correct(_row("repairable", "success", success=False))  # ended success, the task is not done
    assert correct(_row("limit:reachability", kinds=["unknown_entity", "reachability"]))
    assert not correct(_row("limit:reachability", kinds=["collision"]))
    assert not correct(_row("limit:collision", "success", kinds=["collision"]))
    assert correct(_row("unrepairable"))
    assert not correct(_row("unrepairable", "success"))
    assert not correct(_row("nominal_equivalent", "crashed"))


def test_summary_counts_loops_false_alarms_and_second_exposure():
    rows = [_row("nominal_equivalent", "success"), _row("nominal_equivalent", "failed", ["unexpected_configuration"]),
            _row("repairable", "failed", ["precondition"], loop=True),
            _row("repairable", "success", ["unknown_entity"],
                 second_exposure={"status": "success", "attempts": 0, "achieved": True}),
            _row("repairable", "success", ["physical"], configuration="retry"),
            _row("repairable", "success", ["verification"],  # its second run claims success, the task is not done
                 second_exposure={"status": "success", "attempts": 0, "achieved": False})]
    summary = summarise(rows)
    assert summary["loops"] == 1
    assert summary["false_alarms"]["count"] == 1 and summary["false_alarms"]["of"] == 2
    assert summary["second_exposure"]["repaired"] == 2 and summary["second_exposure"]["zero_attempts"] == 1
    assert summary["second_exposure"]["false_successes"] == 1
    assert summary["confusion"]["nominal_equivalent"] == {"none": 1, "unexpected_configuration": 1}
    table = {(r["expected"], r["configuration"]): r for r in summary["table"]}
    assert table[("repairable", "dual")]["correct"] == 2 and table[("repairable", "dual")]["episodes"] == 3
    assert table[("all", "dual")]["episodes"] == 5
    low, high = table[("all", "dual")]["wilson95"]
    assert low < table[("all", "dual")]["rate"] < high


def test_dual_beats_only_with_disjoint_intervals():
    rows = [_row("repairable", "success", configuration="dual") for _ in range(30)]
    rows += [_row("repairable", "failed", configuration="retry") for _ in range(30)]
    rows += [_row("repairable", "success" if k % 2 else "failed", configuration="symbolic") for k in range(30)]
    found = verdicts(summarise(rows))
    assert found["retry"]["beats"] and not found["retry"]["beaten"]
    assert found["symbolic"]["beats"]  # 1.0 [0.89, 1] against 0.5 [0.33, 0.67]
    few = verdicts(summarise([_row("repairable", "success"), _row("repairable", configuration="retry")]))
    assert not few["retry"]["beats"] and not few["retry"]["beaten"]  # one run each: the intervals overlap


def test_each_variant_counts_under_every_perturbation_class_it_carries():
    manifest = {"variants": [
        {"name": "v0", "changes": []},
        {"name": "v1", "changes": [{"kind": "shift", "object": "a"}, {"kind": "turn", "object": "a"}]},
        {"name": "v2", "changes": [{"kind": "rotate", "object": "a", "rpy": [90, 0, 30]}]},
        {"name": "v3", "changes": [{"kind": "rotate", "object": "a", "rpy": [0, -180, 0]}]},
        {"name": "v4", "changes": [{"kind": "remove", "object": "a", "spare": "spare_a"},
                                   {"kind": "remove", "object": "b", "spare": None}]},
        {"name": "v5", "changes": [{"kind": "obstacles"}, {"kind": "out_of_reach", "object": "a"}]}]}
    assert perturbation_classes(manifest) == {
        "v0": ["none"], "v1": ["shift", "turn"], "v2": ["on a side"], "v3": ["upside down"],
        "v4": ["missing, spare", "missing, no spare"], "v5": ["obstacle", "out of reach"]}


def test_the_class_table_counts_reached_outcomes_per_class_and_configuration():
    rows = [{**_row("repairable", "success"), "variant": "v1"}, {**_row("repairable", "failed"), "variant": "v2"},
            {**_row("repairable", "failed"), "variant": "v1", "configuration": "retry"},
            {**_row("limit:reachability", "failed", ["reachability"]), "variant": "v5"}]
    classes = {"v1": ["shift", "turn"], "v2": ["on a side"], "v5": ["out of reach"]}
    table = {(r["class"], r["configuration"]): r for r in summarise(rows, classes=classes)["classes"]}
    assert [(c, n) for c, n in table] == [("shift", "dual"), ("shift", "retry"), ("turn", "dual"),
                                          ("turn", "retry"), ("on a side", "dual"), ("out of reach", "dual")]
    assert table[("shift", "dual")]["correct"] == 1 and table[("shift", "retry")]["correct"] == 0
    assert table[("on a side", "dual")]["rate"] == 0.0 and table[("out of reach", "dual")]["rate"] == 1.0
    assert table[("turn", "dual")]["expected"] == {"repairable": 1}
    assert summarise(rows)["classes"] == []


def test_class_tables_of_several_campaigns_add_up():
    one = [{"class": "shift", "configuration": "dual", "episodes": 3, "correct": 2, "expected": {"repairable": 3}}]
    two = [{"class": "shift", "configuration": "dual", "episodes": 2, "correct": 2, "expected": {"repairable": 2}},
           {"class": "none", "configuration": "dual", "episodes": 1, "correct": 0,
            "expected": {"nominal_equivalent": 1}}]
    pooled = pool_classes([one, two])
    assert [(r["class"], r["episodes"], r["correct"]) for r in pooled] == [("none", 1, 0), ("shift", 5, 4)]
    assert pooled[1]["expected"] == {"repairable": 5}
    assert list(pooled[1]["wilson95"]) == list(wilson_interval(4, 5))
