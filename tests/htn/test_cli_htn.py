"""``bt-meta plan`` and ``bt-meta validate``: output, JSON shape and exit statuses."""

from __future__ import annotations

import json

from bt_meta.cli import main
from bt_meta.resources import shipped_tree

LETTERS = str(shipped_tree("letters.yaml"))


def test_plan_json_is_one_object_with_plan_tree_and_stats(capsys):
    assert main(["plan", LETTERS, "--problem", "A", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["status"] == "success"
    assert payload["plan"][4] == ["place", "b5", "1.5", "1"]
    assert payload["tree"]["roots"] == ["n0"]
    assert payload["tree"]["nodes"][0]["method"] == "A_legs_bar_apex"
    assert "state_before" not in payload["tree"]["nodes"][0]
    assert payload["stats"]["plan_length"] == 6


def test_plan_json_with_states(capsys):
    assert main(["plan", LETTERS, "--problem", "A", "--json", "--states"]) == 0
    node = json.loads(capsys.readouterr().out)["tree"]["nodes"][0]
    assert ["available", "b0"] in node["state_before"]


def test_plan_text_prints_the_plan_and_the_indented_tree(capsys):
    assert main(["plan", LETTERS, "--problem", "H"]) == 0
    out = capsys.readouterr().out
    assert "plan found: 8 steps" in out
    assert "    6  place(b6, 1, 1)" in out
    assert "  n0 draw_H()  [method H_legs_bar]" in out
    assert "      n10 place(b6, 1, 1)  [step 6]" in out


def test_no_plan_and_budget_exhaustion_exit_1_with_the_reason(capsys):
    assert main(["plan", LETTERS, "--problem", "A_bar_other_colour"]) == 1
    assert "no plan: every method and binding failed" in capsys.readouterr().out
    assert main(["plan", LETTERS, "--problem", "A", "--max-nodes", "2", "--json"]) == 1
    payload = json.loads(capsys.readouterr().out)
    assert payload["status"] == "budget_exhausted" and payload["plan"] == [] and payload["tree"] is None
    assert payload["message"].startswith("budget exhausted: node budget of 2 expansions exhausted")


def test_a_missing_or_unknown_problem_is_an_input_error(capsys):
    assert main(["plan", LETTERS]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{LETTERS}: the file has several problems, choose one with --problem: A, H, ")
    assert main(["plan", LETTERS, "--problem", "Z"]) == 2
    assert "no problem named 'Z'; problems: A, H, A_bar_other_colour" in capsys.readouterr().err
    assert main(["plan", LETTERS, "--problem", "A", "--max-nodes", "0"]) == 2


def test_a_malformed_file_gets_one_located_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("domain:\n  predicates: {p: []}\n  primitives:\n    go: {precondition: p() and q()}\n")
    for command in (["plan", str(bad)], ["validate", str(bad)]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err == f"{bad}:4:32: unknown predicate 'q' (known: p)\n"


def test_validate_summarises_a_good_file(capsys):
    assert main(["validate", LETTERS]) == 0
    assert capsys.readouterr().out == f"{LETTERS}: ok (2 primitives, 8 methods, 5 problems)\n"


EXTERNAL_DOMAIN = """\
domain:
  name: reach
  predicates:
    at: [?b]
  external:
    reachable: [?b]
  primitives:
    pick:
      parameters: [?b]
      precondition: reachable(?b)
      add: [at(?b)]
  tasks:
    fetch: [?b]
  methods:
    - name: fetch_it
      task: fetch(?b)
      subtasks: [pick(?b)]
problems:
  near:
    tasks: [fetch(cup)]
"""

REACH_PLUGIN = """\
from bt_meta.plugins import hookimpl


@hookimpl
def bt_meta_external_predicate(name, args, state):
    if name == "reachable":
        return args[0] == "cup"
    return None
"""


def test_plan_asks_plugins_for_external_predicates(tmp_path, capsys):
    task_file = tmp_path / "reach.yaml"
    task_file.write_text(EXTERNAL_DOMAIN, encoding="utf-8")
    assert main(["plan", str(task_file), "--json", "--no-entry-points"]) == 1  # nobody answers reachable/1
    assert "reachable" in capsys.readouterr().err
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "reach.py").write_text(REACH_PLUGIN, encoding="utf-8")
    assert main(["plan", str(task_file), "--json", "--no-entry-points"]) == 0  # the project's plugins/ folder
    assert json.loads(capsys.readouterr().out)["plan"] == [["pick", "cup"]]
