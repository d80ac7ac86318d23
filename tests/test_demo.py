"""``bt-meta demo``: one quick run into a temporary folder, then a second run on the same folder.

The first run records the demonstrations into a new memory, runs the variants with monitors and repairs, and
writes report.html and summary.json; the second reuses the memory (nothing recorded again) and the refinements the
first one learned (zero attempts on the variants the first run repaired). Plus the SVG pictures and the input
errors, which need no simulator.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ElementTree

import pytest

from bt_meta.cli import main
from bt_meta.demo.report import grid_svg
from bt_meta.demo.scenario import demonstrations, variants
from bt_meta.plotting import line_plot
from bt_meta.runs.svg import TreeNode, tree_from_behaviour, tree_svg


def test_tree_svg_colours_nodes_by_status():
    tree = TreeNode("plan", "Sequence", "FAILURE", children=[
        TreeNode("n2 place(b0, 0, 0)", "Monitor", "SUCCESS", "n2"),
        TreeNode("n3 place(b5, 1.5, 1)", "Monitor", "FAILURE", "n3"),
        TreeNode("n4 place(b4, 1.5, 2)", "Monitor", "INVALID", "n4"),
    ])
    svg = tree_svg(tree, title="segment 1")
    root = ElementTree.fromstring(svg)  # well-formed XML
    assert root.tag.endswith("svg")
    assert svg.count("#e53935") >= 2 and "#4caf50" in svg and "segment 1" in svg
    assert TreeNode.from_dict(tree.to_dict()) == tree


def test_tree_from_behaviour_derives_sequence_and_guard_statuses():
    from bt_meta.bt.compiler import compile_plan
    from bt_meta.htn import load_task_file, plan
    from bt_meta.resources import trees_dir

    task_file = load_task_file(trees_dir() / "letters.yaml")
    result = plan(task_file.domain, task_file.problem("A"))
    root = compile_plan(result.tree, task_file.domain)
    steps = {n.step: n.id for n in result.tree.walk() if n.kind == "primitive"}
    statuses = {steps[0]: "SUCCESS", steps[1]: "SUCCESS", steps[2]: "FAILURE"}
    tree = tree_from_behaviour(root, statuses)
    assert tree.status == "FAILURE"
    legs = tree.children[0].children[:2]
    assert [leg.status for leg in legs] == ["SUCCESS", "FAILURE"]
    assert legs[0].children[0].kind == "CheckCondition" and legs[0].children[0].status == "SUCCESS"
    assert [c.status for c in legs[1].children] == ["SUCCESS", "FAILURE", "INVALID"]  # guard, failed step, next
    # the apex was never reached: its sequence and guard stay INVALID
    apex = tree.children[0].children[-1]
    assert apex.status == "INVALID" and apex.children[0].status == "INVALID"


def test_line_plot_and_grid_pictures_are_well_formed():
    svg = line_plot({"R_n this run": [(0, 90.0), (1, None), (2, 180.0)], "mean": [(0, 180.0), (2, 180.0)]},
                        title="R_n", x_label="step", y_label="deg", bands={"mean": [(0, 170, 190), (2, 175, 185)]},
                        markers=[(0, "failure")])
    ElementTree.fromstring(svg)
    assert "failure" in svg and "R_n this run" in svg and "mean: min-max" in svg  # drawn by matplotlib
    assert "<path" in svg and "fill-opacity: 0.3" in svg  # the band is filled, visibly
    assert "no data" in line_plot({}, title="empty", x_label="x", y_label="y")
    grid = grid_svg("..bb\nr..b", title="remembered")
    ElementTree.fromstring(grid)
    assert grid.count("<rect") == 8


def test_quick_scenario_is_smaller():
    assert len(demonstrations(0, quick=True)) < len(demonstrations(0))
    assert {v.family for v in variants(0, quick=True)} == {"letters", "magnetic", "housing"}
    assert len(variants(0, quick=True)) < len(variants(0))


def test_out_must_be_a_folder(tmp_path, capsys):
    target = tmp_path / "a-file"
    target.write_text("x")
    assert main(["demo", "--out", str(target)]) == 2
    assert "--out must be a folder, not a file" in capsys.readouterr().err


@pytest.mark.slow
def test_quick_demo_twice_on_the_same_folder(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quick"]) == 0
    printed = capsys.readouterr().out
    assert "[1/3] recording" in printed and "tick" in printed and "report:" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fresh_memory"] is True and summary["completed"] is True
    assert [d["status"] for d in summary["demonstrations"]] == ["recorded"] * len(demonstrations(0, quick=True))
    expected = [(v.family, v.variant) for v in variants(0, quick=True)]
    runs = summary["runs"]
    assert [(r["family"], r["variant"]) for r in runs] == expected * 2
    assert [r["pass"] for r in runs] == [1] * len(expected) + [2] * len(expected)
    for run in runs:
        assert run["status"] in ("success", "failed", "no_plan"), run
        assert run["status"] == "success" or run["stop_reason"], run  # a run not repaired says why
    # every variant of the first pass failed a monitor or a verification at least once: the variants differ
    assert all(r["failure_kinds"] for r in runs[: len(expected)])
    report = (out / "report.html").read_text()
    for section in ("Summary", "Demonstrations recorded", "First pass", "Second pass", "Repair log",
                    "Learned refinements", "Behaviour tree", "Keypoint relations", "Grid-maps",
                    "data:image/png;base64,", "<svg"):
        assert section in report, section
    repaired = {(r["family"], r["variant"]) for r in runs[: len(expected)] if r["repaired"]}
    learned = len(summary["refinements"])
    assert learned >= len([r for r in runs[: len(expected)] if r["refinement_saved"]])

    # second run: same memory, nothing recorded again, the learned refinements used with zero attempts
    assert main(["demo", "--out", str(out), "--quick", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["fresh_memory"] is False
    assert {d["status"] for d in again["demonstrations"]} == {"reused"}
    assert len(again["refinements"]) == learned  # nothing new needed learning for the repaired variants
    for run in again["runs"]:
        if (run["family"], run["variant"]) not in repaired:
            continue
        assert run["status"] == "success", run
        assert run["attempts"] == 0 and run["refinements_used"], run
    assert json.loads((out / "summary.json").read_text()) == again
