"""The judge's geometric checks on hand-built states of the simulator: each holds exactly when the world says so."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.campaign.episode import variant_world
from bt_meta.judge.checks import covered, evaluate, footprint
from bt_meta.judge.success import success_check
from bt_meta.resources import trees_dir
from bt_meta.world.simulation.objects import LB
from bt_meta.world.simulation.scenes import load_scene


def _square(cx, cy, side):
    h = side / 2.0
    return np.array([[cx - h, cy - h, 0], [cx + h, cy - h, 0], [cx + h, cy + h, 0], [cx - h, cy + h, 0]])


def test_coverage_tolerates_a_small_gap_not_a_hole():
    target = np.vstack([_square(-LB / 2, 0, LB), _square(LB / 2, 0, LB)])  # a 1x2 outline
    left, right = footprint(_square(-LB / 2 - 0.001, 0, LB)), footprint(_square(LB / 2 + 0.001, 0, LB))
    assert covered(target, [left, right], 0.015, 0.005)[0] == covered(target, [left, right], 0.015, 0.005)[1]
    hit, total = covered(target, [left], 0.015, 0.005)
    assert 0 < hit < total  # half of it bare
    far = footprint(_square(LB / 2 + 0.03, 0, LB))
    assert covered(target, [left, far], 0.015, 0.005)[0] < total


@pytest.mark.slow
def test_cells_covered_and_uncovered_on_the_letters_scene():
    task = trees_dir() / "letters.yaml"
    task_file, problem, world = variant_world(task, "A", load_scene("letters_A").path, None, 0)
    try:
        sim = world.sim
        # lay b0 on cell (0, 0) by hand; nothing covers cell (3, 0)
        x, y, yaw = world.ground_cell("letter", "0", "0")
        sim.move_object("b0", [x, y, sim.object_pose("b0")[2], 0.0, 0.0, yaw])
        sim.settle(30)
        assert evaluate("at_cell", ("b0", "0", "0"), {}, world)[0]
        assert evaluate("at_cell", ("b1", "0", "0"), {}, world)[0]  # any block covering it will do
        ok, why = evaluate("at_cell", ("b2", "3", "0"), {}, world)
        assert not ok and "not covered" in why
        sim.move_object("b0", [x + 0.03, y, sim.object_pose("b0")[2], 0.0, 0.0, yaw])  # 3 cm off: a hole
        sim.settle(30)
        assert not evaluate("at_cell", ("b0", "0", "0"), {}, world)[0]
        assert not success_check(task_file, problem, world.grounding).evaluate(world)[0]
    finally:
        world.close()


@pytest.mark.slow
def test_faces_joins_grip_and_insertion_on_hand_built_states():
    task = trees_dir() / "magnetic_attach.yaml"
    _, _, world = variant_world(task, "nominal", load_scene("magnetic_attach").path, None, 0)
    try:
        sim = world.sim
        assert evaluate("on_face", ("active_part", "+z"), {}, world)[0]
        pose = list(sim.object_pose("active"))
        sim.move_object("active", [pose[0], pose[1], pose[2] + 0.01, math.pi / 2, 0.0, 0.0])
        sim.settle(60)
        ok, why = evaluate("on_face", ("active_part", "+z"), {}, world)
        assert not ok and "off up" in why
        assert not evaluate("attached", ("active_part", "reference_part"), {}, world)[0]
        assert evaluate("gripper", ("open",), {}, world)[0] and not evaluate("gripper", ("closed",), {}, world)[0]
        assert not evaluate("held", ("active_part",), {}, world)[0]
        ok, why = evaluate("lifted", ("active_part", "reference_part"), {}, world)
        assert not ok and "still on the table" in why
        ok, why = evaluate("at_pose", ("staging",), {}, world)
        assert not ok and "from staging" in why
        assert not evaluate("held", ("ghost",), {}, world)[0]  # a symbol the world cannot ground: not held
    finally:
        world.close()
    task = trees_dir() / "housing_insertion.yaml"
    _, _, world = variant_world(task, "nominal", load_scene("housing_insertion").path, None, 0)
    try:
        ok, why = evaluate("inserted", ("housing", "housing_hole"), {}, world)
        assert not ok and "not in board's hole" in why
        sim = world.sim
        hole, _ = sim.feature("board", "hole")
        end, _ = sim.feature("housing")
        pose = list(sim.object_pose("housing"))
        moved = [pose[0] + hole[0] - end[0], pose[1] + hole[1] - end[1], pose[2] + hole[2] - end[2], *pose[3:]]
        sim.move_object("housing", moved)  # its insertable end put on the hole, not settled
        assert evaluate("inserted", ("housing", "housing_hole"), {}, world)[0]
    finally:
        world.close()
