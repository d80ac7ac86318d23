"""The demo's outcomes are decided by the same judge as the campaigns': each demo family's shipped family file."""

from __future__ import annotations

import pytest

from bt_meta.demo.scenario import FAMILIES
from bt_meta.htn import load_task_file
from bt_meta.judge.success import success_check_file
from bt_meta.resources import trees_dir
from bt_meta.world.simulation.sim_world import load_grounding


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_every_demo_family_is_judged_by_a_shipped_family_file(name):
    demo = FAMILIES[name]
    task = trees_dir() / demo.task_file
    task_file = load_task_file(task)
    check = success_check_file(demo.success_file(), task_file, task_file.problem(demo.problem),
                               load_grounding(task_file.domain.name, task))
    assert demo.success_file().is_file() and check.checks
    assert {c.kind for c in check.checks} <= {"at_cell", "at_pose", "gripper", "attached", "inserted"}


def test_the_judge_needs_a_simulator():
    task = trees_dir() / "letters.yaml"
    task_file = load_task_file(task)
    check = success_check_file(FAMILIES["letters"].success_file(), task_file, task_file.problem("A"),
                               load_grounding(task_file.domain.name, task))
    assert check.evaluate(object()) == (None, "no simulator to ask")
