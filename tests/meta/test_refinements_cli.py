"""``bt-meta refinements ls`` shows what a refinement perceived (its facts) and the goal its repair rewrote, in the
text listing and in ``--json``; a refinement without them gets no such lines."""

from __future__ import annotations

import json

from bt_meta.cli import main
from bt_meta.meta.refinements import Refinement, RefinementStore

FACTS = {"add": [["colour", "b5", "red"], ["shape", "b5", "1x1"], ["block", "b6"]],
         "delete": [["colour", "b5", "blue"], ["shape", "b5", "1x2"]]}
GOAL = [["at", "b5", "1", "1"], ["at", "b6", "2", "1"]]


def _store(tmp_path):
    memory = tmp_path / "memory.sqlite"
    with RefinementStore.open(memory) as store:
        store.add(Refinement(domain="attach", task="MagneticAttach(active, reference)", method="refined_pose",
                             precondition="true", subtasks=["MoveTo(g_alt)"]))
        store.add(Refinement(domain="letters", task="draw_A_bar()", method="refined_draw_A_bar",
                             precondition="seen(b5, colour, red)", subtasks=["place(b5, 1, 1)", "place(b6, 2, 1)"],
                             repair={"attempts": 1, "proposals": [{"action": "splice", "plugin": "object_substitution",
                                                                   "change": "b5 -> b5, b6"}]},
                             facts=FACTS, goal=GOAL))
    return memory


def _block(out: str, method: str) -> list[str]:
    """The lines of one refinement in the text listing (its header line and the indented ones under it)."""
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if f"  ->  {method}  " in line)
    end = next((i for i in range(start + 1, len(lines)) if not lines[i].startswith("    ")), len(lines))
    return lines[start:end]


def test_ls_shows_the_perceived_facts_and_the_rewritten_goal(tmp_path, capsys):
    memory = _store(tmp_path)
    assert main(["refinements", "ls", "--memory", str(memory)]) == 0
    out = capsys.readouterr().out
    block = _block(out, "refined_draw_A_bar")
    assert ("    perceived facts: add colour(b5, red), shape(b5, 1x1), block(b6); "
            "delete colour(b5, blue), shape(b5, 1x2)") in block
    assert "    goal (rewritten): at(b5, 1, 1), at(b6, 2, 1)" in block
    assert any("splice by object_substitution: b5 -> b5, b6" in line for line in block)
    plain = _block(out, "refined_pose")  # nothing perceived, goal unchanged: no empty lines about them
    assert not any("perceived facts" in line or "goal" in line for line in plain)
    assert len(plain) == 5
    assert plain[1] == "    robot unknown; active; replayed 0 time(s), failed 0"


def test_ls_json_carries_facts_and_goal(tmp_path, capsys):
    memory = _store(tmp_path)
    assert main(["refinements", "ls", "--json", "--memory", str(memory)]) == 0
    listed = {r["method"]: r for r in json.loads(capsys.readouterr().out)}
    assert listed["refined_draw_A_bar"]["facts"] == FACTS and listed["refined_draw_A_bar"]["goal"] == GOAL
    assert "facts" not in listed["refined_draw_A_bar"]["repair"]  # once, at the top level
    assert listed["refined_pose"]["facts"] == {} and listed["refined_pose"]["goal"] is None


def test_ls_of_one_domain(tmp_path, capsys):
    memory = _store(tmp_path)
    assert main(["refinements", "ls", "--domain", "attach", "--memory", str(memory)]) == 0
    out = capsys.readouterr().out
    assert "refined_pose" in out and "refined_draw_A_bar" not in out and "perceived facts" not in out
    assert main(["refinements", "ls", "--domain", "nope", "--memory", str(memory)]) == 0
    assert capsys.readouterr().out.startswith("no refinements of domain nope in ")
