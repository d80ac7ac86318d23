"""``bt-meta bench htn``: the benchmark's problems plan with our planner, every plan is checked, the CLI's shape."""

from __future__ import annotations

import json
import sys

import pytest

from bt_meta.bench import htn as bench
from bt_meta.cli import main

pytest.importorskip("gtpyhop")


@pytest.fixture(scope="module")
def gtpyhop():
    return bench.import_gtpyhop()


@pytest.fixture(scope="module")
def problems(gtpyhop):
    return {p.name: p for p in bench.build_problems(gtpyhop, seed=1)}


def _plan_ours(problem: bench.BenchProblem) -> dict:
    return bench.OurPlanner([problem]).run_once(problem, max_seconds=60)


def test_problems_come_from_gtpyhops_examples(problems):
    assert {"sussman", "bw_large_d", "bw_rand_50", "blocks_100", "blocks_200"} <= set(problems)
    assert sorted(n for n in problems if n.startswith("childsnack_")) == [f"childsnack_p{i:02d}" for i in range(1, 31)]
    sussman = problems["sussman"]
    # GTPyhop's Sussman anomaly: c on a, a and b on the table; the goal is a on b on c.
    assert set(sussman.init) >= {("on", "c", "a"), ("on_table", "a"), ("on_table", "b"), ("clear", "c")}
    assert ("clear", "a") not in sussman.init
    assert set(sussman.goal) == {("on", "a", "b"), ("on", "b", "c")}
    assert problems["bw_rand_50"].size == "50 blocks"
    assert problems["childsnack_p30"].size == "500 children"


def test_sussman_plans_with_our_planner_and_the_plan_is_correct(problems):
    outcome = _plan_ours(problems["sussman"])
    assert outcome["status"] == "success", outcome["message"]
    assert outcome["valid"] is True
    assert outcome["plan_length"] == 6
    assert outcome["tree_nodes"] > outcome["plan_length"]


def test_generated_ten_block_problem_plans_and_the_plan_is_correct():
    pos, goal_pos = bench.random_blocks_problem(10, seed=7)
    problem = bench._blocks_problem("blocks_10", pos, goal_pos)
    outcome = _plan_ours(problem)
    assert outcome["status"] == "success", outcome["message"]
    assert outcome["valid"] is True
    assert outcome["plan_length"] % 2 == 0 and outcome["plan_length"] <= 4 * 10


def test_small_childsnack_plans_and_the_plan_is_correct(problems):
    outcome = _plan_ours(problems["childsnack_p01"])
    assert outcome["status"] == "success", outcome["message"]
    assert outcome["valid"] is True
    assert outcome["plan_length"] == 5 * 10


def test_gtpyhop_plans_the_same_problem_and_its_plan_is_checked_too(gtpyhop, problems):
    domains = {"blocks": bench._load_blocks_htn_domain(gtpyhop)}
    outcome = bench.run_gtpyhop(gtpyhop, domains, problems["sussman"], "recursive_dfs", repeat=1)
    assert outcome["status"] == "success" and outcome["valid"] is True
    assert outcome["plan_length"] == 6


def test_random_blocks_problem_is_seeded():
    assert bench.random_blocks_problem(20, seed=3) == bench.random_blocks_problem(20, seed=3)
    assert bench.random_blocks_problem(20, seed=3) != bench.random_blocks_problem(20, seed=4)
    pos, goal = bench.random_blocks_problem(20, seed=3)
    assert sorted(pos) == sorted(goal) == list(range(1, 21))


def test_blocks_validator_rejects_illegal_steps_and_unreached_goals():
    pos = {"c": "a", "a": "table", "b": "table"}
    goal = {"a": "b", "b": "c"}
    good = [("unstack", "c", "a"), ("putdown", "c"), ("pickup", "b"), ("stack", "b", "c"), ("pickup", "a")]
    good.append(("stack", "a", "b"))
    assert bench.validate_blocks_plan(pos, good, goal) is None
    assert "step 0 pickup('a',)" in bench.validate_blocks_plan(pos, [("pickup", "a")], goal)
    assert "goal not reached" in bench.validate_blocks_plan(pos, good[:2], goal)
    assert "unknown action" in bench.validate_blocks_plan(pos, [("fly", "a")], goal)
    assert "is not clear" in bench.validate_blocks_plan(pos, good, goal, {"b": True})


def test_childsnack_validator_rejects_gluten_for_an_allergic_child(problems):
    problem = problems["childsnack_p01"]
    allergic = sorted(a[1] for a in problem.init if a[0] == "allergic_gluten")[0]
    place = next(a[2] for a in problem.init if a[0] == "waiting" and a[1] == allergic)
    bread = sorted(a[1] for a in problem.init if a[0] == "at_kitchen_bread")[0]
    content = sorted(a[1] for a in problem.init if a[0] == "at_kitchen_content")[0]
    plan = [
        ("make_sandwich", "sandw1", bread, content),
        ("put_on_tray", "sandw1", "tray1"),
        ("move_tray", "tray1", "kitchen", place),
        ("serve_sandwich", "sandw1", allergic, "tray1", place),
    ]
    error = bench.validate_childsnack_plan(problem.init, plan, problem.goal)
    assert error is not None and "step 3 serve_sandwich" in error and "not_allergic_gluten" in error
    assert "goal not reached" in bench.validate_childsnack_plan(problem.init, plan[:3], problem.goal)


def test_cli_json_shape_for_sussman(capsys):
    assert main(["bench", "htn", "--only", "sussman", "--json", "--repeat", "1"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["benchmark"] == "htn"
    assert report["baseline"].startswith("GTPyhop ")
    assert report["strategies"] == list(bench.STRATEGIES)
    [row] = report["problems"]
    assert row["name"] == "sussman"
    assert row["ours"]["status"] == "success" and row["ours"]["plan_length"] == 6 and row["ours"]["valid"]
    assert set(row["gtpyhop"]) == set(bench.STRATEGIES)
    for strategy in bench.STRATEGIES:
        assert row["gtpyhop"][strategy]["plan_length"] == 6
        assert row["ratio"][strategy] == pytest.approx(row["gtpyhop"][strategy]["seconds"] / row["ours"]["seconds"])
    assert set(report["summary"]) == {"ours_failed", "gtpyhop_failures", "min_ratio", "target_met"}


def test_cli_table_names_both_planners(capsys):
    assert main(["bench", "htn", "--only", "sussman", "--repeat", "1", "--strategy", "recursive_dfs"]) == 0
    out = capsys.readouterr().out
    assert "GTPyhop" in out and "sussman" in out and "rec ratio" in out


def test_unknown_problem_is_an_input_error(capsys):
    assert main(["bench", "htn", "--only", "no_such_problem"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bt-meta bench htn: --only ")
    assert "no_such_problem" in err and "matches no problem" in err and "sussman" in err


def test_missing_gtpyhop_is_a_clear_error(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "gtpyhop", None)  # makes `import gtpyhop` raise ImportError
    assert main(["bench", "htn", "--only", "sussman"]) == 2
    err = capsys.readouterr().err
    assert "GTPyhop is not installed" in err and "bt-meta[bench]" in err


def test_repeat_below_one_is_an_input_error(capsys):
    assert main(["bench", "htn", "--only", "sussman", "--repeat", "0"]) == 2
    assert capsys.readouterr().err.strip() == "bt-meta bench htn: --repeat must be at least 1, got 0"


def test_negative_min_seconds_is_an_input_error(capsys):
    assert main(["bench", "htn", "--only", "sussman", "--min-seconds", "-1"]) == 2
    assert capsys.readouterr().err.strip() == "bt-meta bench htn: --min-seconds must be 0 or more, got -1.0"


def test_fast_contenders_run_until_their_time_adds_up_and_slow_ones_stop_after_repeat():
    """The runner's bookkeeping with contenders that report fixed times (no clock involved)."""
    calls = {"fast": 0, "slow": 0, "broken": 0}

    def contender(name: str, seconds: list[float], status: str = "success"):
        def run() -> dict:
            calls[name] += 1
            return {"status": status, "seconds": seconds[(calls[name] - 1) % len(seconds)], "message": ""}
        return run

    best = bench._interleaved_best(3, {
        "fast": contender("fast", [0.003, 0.001, 0.002]),
        "slow": contender("slow", [0.5, 0.4]),
        "broken": contender("broken", [0.001], status="no_plan"),
    }, min_seconds=0.1)
    assert calls == {"fast": 50, "slow": 3, "broken": 1}  # 50 runs of 2 ms on average make 0.1 s
    assert best["fast"]["seconds"] == 0.001 and best["fast"]["runs"] == 50
    assert best["slow"]["seconds"] == 0.4 and best["slow"]["runs"] == 3
    assert best["broken"]["status"] == "no_plan" and best["broken"]["runs"] == 1
    calls.update(fast=0)
    capped = bench._interleaved_best(1, {"fast": contender("fast", [0.0])}, min_seconds=1.0)
    assert capped["fast"]["runs"] == bench.MAX_ROUNDS
