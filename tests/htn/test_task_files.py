"""The shipped task files validate and plan as the paper's scenes need."""

from __future__ import annotations

import pytest

from bt_meta.htn import load_task_file, plan
from bt_meta.resources import shipped_tree


def shapes(problem, names):
    facts = {atom[1]: atom[2] for atom in problem.init if atom[0] == "shape"}
    return [facts[name] for name in names]


def test_letter_A_draws_its_bar_with_the_1x2_block():
    taskfile = load_task_file(shipped_tree("letters.yaml"))
    problem = taskfile.problems["A"]
    result = plan(taskfile.domain, problem)
    assert result.status == "success"
    bar = [n for n in result.tree.walk() if n.task == ("draw_A_bar",)]
    assert len(bar) == 1 and bar[0].method == "A_bar_one_1x2"
    bar_blocks = [result.tree.nodes[c].task[1] for c in bar[0].children]
    assert shapes(problem, bar_blocks) == ["1x2"]
    assert ["place", "b5", "1.5", "1"] in [a.as_list() for a in result.plan]
    assert len(result.plan) == 6


def test_letter_H_draws_its_bar_with_two_1x1_blocks():
    taskfile = load_task_file(shipped_tree("letters.yaml"))
    problem = taskfile.problems["H"]
    result = plan(taskfile.domain, problem)
    assert result.status == "success"
    bar = [n for n in result.tree.walk() if n.task == ("draw_H_bar",)]
    assert len(bar) == 1 and bar[0].method == "H_bar_two_1x1"
    bar_blocks = [result.tree.nodes[c].task[1] for c in bar[0].children]
    assert shapes(problem, bar_blocks) == ["1x1", "1x1"]
    assert len(result.plan) == 8


@pytest.mark.parametrize("variant", ["A_bar_other_colour", "A_two_1x1_same_colour", "A_two_1x1_different_colours"])
def test_the_variants_of_A_have_no_symbolic_plan(variant):
    taskfile = load_task_file(shipped_tree("letters.yaml"))
    result = plan(taskfile.domain, taskfile.problems[variant])
    assert result.status == "no_plan"
    assert "draw_A_bar(): no method applies (tried A_bar_one_1x2)" in result.message


def test_magnetic_attach_decomposes_into_move_to_and_grasp_and_verifies_at_the_staging_pose():
    taskfile = load_task_file(shipped_tree("magnetic_attach.yaml"))
    assert set(taskfile.domain.primitives) == {"MoveTo", "Grasp"}
    result = plan(taskfile.domain, taskfile.problems["nominal"])
    assert result.status == "success"
    assert {a.name for a in result.plan} == {"MoveTo", "Grasp"}
    assert [a.as_list() for a in result.plan[:8]] == [
        ["MoveTo", "active_above"], ["MoveTo", "active_grasp"], ["Grasp"], ["MoveTo", "active_above"],
        ["MoveTo", "joint_above"], ["MoveTo", "joint"], ["Grasp"], ["MoveTo", "joint_above"]]
    assert result.plan[-1].as_list() == ["MoveTo", "staging"]
    tasks = [n.name for n in result.tree.walk() if n.kind == "compound"]
    assert tasks[:2] == ["AttachAndVerify", "MagneticAttach"] and "VerifyAttachment" in tasks
    assert plan(taskfile.domain, taskfile.problems["attach_only"]).status == "success"


def test_housing_insertion_nominal_plans_and_the_upside_down_variant_does_not():
    taskfile = load_task_file(shipped_tree("housing_insertion.yaml"))
    result = plan(taskfile.domain, taskfile.problems["nominal"])
    assert result.status == "success"
    assert ["Insert", "housing", "housing_hole"] in [a.as_list() for a in result.plan]
    assert ("inserted", "housing", "housing_hole") in result.state
    assert plan(taskfile.domain, taskfile.problems["upside_down"]).status == "no_plan"


def test_every_primitive_of_the_shipped_files_keeps_an_expectations_slot():
    for name in ("letters.yaml", "magnetic_attach.yaml", "housing_insertion.yaml"):
        domain = load_task_file(shipped_tree(name)).domain
        assert all(p.expectations == {} for p in domain.primitives.values()), name


def test_the_complete_example_of_the_format_reference_loads_and_plans():
    import re
    from pathlib import Path

    from bt_meta.htn import load_task_text

    doc = (Path(__file__).resolve().parents[2] / "docs" / "task-files.md").read_text(encoding="utf-8")
    example = re.findall(r"```yaml\n(.*?)```", doc, re.S)[0]
    taskfile = load_task_text(example)
    result = plan(taskfile.domain, taskfile.problems["A"], external=lambda name, args, state: True)
    assert result.status == "success"
    assert [a.as_list() for a in result.plan][-1] == ["place", "b5", "1.5", "1"]
