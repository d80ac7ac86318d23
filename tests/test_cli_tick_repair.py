"""``bt-meta tick FILE --world fake --repair``: the meta-reasoner repairs injected faults on the fake world."""

from __future__ import annotations

import json

from bt_meta.cli import main
from bt_meta.resources import trees_dir

LETTERS = str(trees_dir() / "letters.yaml")


def tick(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["tick", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_a_fault_once_is_repaired_by_retrying(capsys):
    code, out, _ = tick(capsys, LETTERS, "--problem", "A", "--world", "fake", "--repair",
                        "--fault", "place(b2, 3, 0)#1=fail:physical")
    assert code == 0
    lines = out.splitlines()
    assert "failure [physical] scripted fault: place(b2, 3, 0) failed" in out
    assert any("repair applied: retry by retry_repair" in line for line in lines)
    assert lines[-1].startswith("SUCCESS after 2 ticks, 1 repair attempt(s); plan: place b0 0 0;")


def test_json_outcome_of_a_repaired_tick_run(capsys):
    code, out, _ = tick(capsys, LETTERS, "--problem", "A", "--repair", "--json",
                        "--fault", "place(b5, 1.5, 1)#1=fail:physical")
    result = json.loads(out)
    assert code == 0 and result["status"] == "SUCCESS" and result["world"] == "fake"
    (attempt,) = result["attempts"]
    assert attempt["kind"] == "physical" and attempt["outcome"] == "repaired"
    assert result["plan"] == result["initial_plan"] and len(result["plan"]) == 6


def test_a_fault_every_time_stops_at_the_attempt_limit(capsys):
    code, out, _ = tick(capsys, LETTERS, "--problem", "A", "--repair", "--max-attempts", "2", "--json",
                        "--fault", "place(b2, 3, 0)=fail:physical")
    result = json.loads(out)
    assert code == 1 and result["status"] == "FAILURE"
    assert 1 <= len(result["attempts"]) <= 2 and result["stop_reason"]
    assert all(f["kind"] == "physical" for f in result["failures"])


def test_repair_needs_a_task_file(capsys):
    xml = str(trees_dir() / "letters_A.xml")
    code, _, err = tick(capsys, xml, "--repair")
    assert code == 2
    assert err.strip().endswith("--repair needs a YAML task file (it replans from the task file's methods)")
    assert "Traceback" not in err
    code, _, err = tick(capsys, LETTERS, "--problem", "A", "--repair", "--max-attempts", "-1")
    assert code == 2 and "--max-attempts must be at least 0" in err
