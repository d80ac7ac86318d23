"""The simulated skills one by one: MoveTo (ticks, IK failure kinds), Grasp (toggle, nothing in reach), Insert and
Place (unknown objects), records for traces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.htn import load_task_file
from bt_meta.resources import trees_dir
from bt_meta.world.base import FAILURE, RUNNING, SUCCESS
from bt_meta.world.simulation.objects import pose_to_matrix
from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout
from bt_meta.world.skills import Grasp, Insert, MoveTo, Place

pytestmark = pytest.mark.slow


def down(x: float, y: float, z: float) -> np.ndarray:
    return pose_to_matrix((x, y, z, math.pi, 0.0, math.pi))


def run(skill, max_ticks: int = 200) -> tuple[str, int]:
    for _ in range(max_ticks):
        status = skill.tick()
        if status != RUNNING:
            return status, skill.ticks
    raise AssertionError(f"{skill.name} still running after {max_ticks} ticks")


@pytest.fixture(scope="module")
def world():
    task_file = load_task_file(trees_dir() / "magnetic_attach.yaml")
    with quiet_stdout():
        w = SimWorld(task_file.domain, task_file.problem("nominal"), load_grounding("magnetic_attach"))
    yield w
    w.close()


@pytest.fixture
def fresh(world):
    """The module's world with the arm back home and nothing held."""
    for arm in world.sim.robot.arms:
        world.release(arm)
    world.sim.set_joint_positions({**world.sim.robot.home, **world.grounding.start_pose(world.sim.robot.name)})
    world.advance()
    return world


def test_move_to_runs_over_several_ticks_and_arrives(fresh):
    target = down(0.62, -0.3, -0.05)
    skill = MoveTo(fresh).begin(target, "test")
    assert skill.tick() == RUNNING
    status, ticks = run(skill)
    assert status == SUCCESS and ticks > 3
    assert np.linalg.norm(fresh.sim.link_transform("right_gripper")[:3, 3] - target[:3, 3]) < 0.003
    record = skill.record()
    assert record["outcome"] == SUCCESS and record["waypoints"] >= 2 and record["ik_time_ms"] > 0
    assert record["position_error"] < 0.003 and len(record["final_gripper"]) == 6


def test_move_to_unreachable_pose_is_a_reachability_failure(fresh):
    before = fresh.sim.joint_positions()
    skill = MoveTo(fresh).begin(down(2.0, -0.2, 0.1), "far away")
    assert skill.tick() == FAILURE
    assert skill.failure.kind == "reachability"
    assert "no IK solution" in skill.failure.message and "far away" in skill.failure.message
    assert skill.failure.evidence["target_xyz"] == pytest.approx([2.0, -0.2, 0.1])
    assert skill.failure.evidence["best_position_error"] > 0.5
    assert fresh.sim.joint_positions() == pytest.approx(before)  # nothing moved


def test_move_to_into_the_table_is_a_collision_naming_the_pair(fresh):
    table_top = fresh.sim.table.top_z
    skill = MoveTo(fresh).begin(down(0.70, -0.25, table_top + 0.03 - 0.06), "into the table")
    assert skill.tick() == FAILURE
    failure = skill.failure
    assert failure.kind == "collision"
    assert "table" in failure.evidence["pair"] and "table" in failure.evidence["objects"]
    assert any(link.startswith(("r_gripper", "right_")) for link in failure.evidence["pair"])
    assert "collides" in failure.message


def test_grasp_with_nothing_in_reach_is_physical(fresh):
    status, _ = run(MoveTo(fresh).begin(down(0.75, -0.45, -0.05)))
    assert status == SUCCESS
    grasp = Grasp(fresh).begin()
    assert grasp.tick() == FAILURE
    assert grasp.failure.kind == "physical" and "nothing is within" in grasp.failure.message
    assert grasp.failure.evidence["nearest"] in fresh.sim.object_names()


def test_grasp_toggles_hold_and_release(fresh):
    sim = fresh.sim
    top = fresh.object_top("active")
    x, y = sim.object_pose("active")[:2]
    assert run(MoveTo(fresh).begin(down(x, y, top + 0.1)))[0] == SUCCESS
    assert run(MoveTo(fresh).begin(down(x, y, top + 0.004)))[0] == SUCCESS
    hold = Grasp(fresh)
    hold.start([])  # the paper's Grasp(): toggle
    assert run(hold)[0] == SUCCESS and sim.held("right") == "active"
    assert hold.record()["action"] == "grasp" and hold.record()["object"] == "active"
    assert run(MoveTo(fresh).begin(down(x, y, top + 0.1)))[0] == SUCCESS
    assert sim.object_pose("active")[2] > sim.table.top_z + 0.08  # it came along
    again = Grasp(fresh)
    again.start([])
    assert run(again)[0] == SUCCESS and sim.held("right") is None
    assert again.record()["action"] == "release"
    # Put it back where the scene had it, for the other tests.
    sim.move_object("active", sim.resting_pose(sim.object_model("active"), (x, y, 0, 0, 0, 0)))
    fresh.advance(2)


def test_unknown_objects_are_unknown_entities(fresh):
    insert = Insert(fresh)
    insert.start(["housing", "reference"])
    assert insert.tick() == FAILURE
    assert insert.failure.kind == "unknown_entity"
    assert insert.failure.evidence["present"] == ["reference", "active"]
    place = Place(fresh)
    place.spec = {"frame": "nowhere"}
    place.start(["ghost", "0", "0"])
    assert place.tick() == FAILURE and place.failure.kind == "internal"  # the frame is checked first
    grasp = Grasp(fresh)
    grasp.start(["ghost"])
    assert grasp.tick() == FAILURE and grasp.failure.kind == "unknown_entity"


def test_move_to_symbol_grounding(fresh):
    move = MoveTo(fresh)
    move.start(["no_such_pose"])
    assert move.tick() == FAILURE
    assert move.failure.kind == "internal" and "known: home, active_above" in move.failure.message
    move = MoveTo(fresh)
    move.start(["joint_above"])
    assert move.record()["target"][:3] == pytest.approx([0.62, -0.10, 0.006])


def test_object_lost_on_the_way_is_physical(fresh):
    sim = fresh.sim
    x, y = sim.object_pose("active")[:2]
    top = fresh.object_top("active")
    assert run(MoveTo(fresh).begin(down(x, y, top + 0.004)))[0] == SUCCESS
    assert run(Grasp(fresh).begin("active", release=False))[0] == SUCCESS
    move = MoveTo(fresh).begin(down(x, y + 0.1, top + 0.1), "carry")
    assert move.tick() == RUNNING
    fresh.release("right")  # the part slips out behind the skill's back
    status, _ = run(move)
    assert status == FAILURE and move.failure.kind == "physical"
    assert "lost" in move.failure.message and move.failure.evidence["held"] is None
    sim.move_object("active", sim.resting_pose(sim.object_model("active"), (x, y, 0, 0, 0, 0)))
    fresh.advance(2)


def test_a_part_out_of_reach_where_it_lies_is_named_in_the_failure(fresh):
    """The approach to the part has no IK solution: ``reachability``, and the evidence names the part
    ``out_of_reach`` (object substitution takes another one; no other motion can pick this one up)."""
    sim = fresh.sim
    home = sim.object_pose("active")
    sim.move_object("active", sim.resting_pose(sim.object_model("active"), (0.98, 0.30, 0, 0, 0, 0)))
    fresh.advance(2)
    try:
        insert = Insert(fresh)
        insert.start(["active", "reference"])
        status, _ = run(insert)
        assert status == FAILURE and insert.failure.kind == "reachability", insert.failure
        assert insert.failure.evidence["failed_phase"] == "approach"
        assert insert.failure.evidence["out_of_reach"] == "active"
    finally:
        sim.move_object("active", home)
        fresh.advance(2)
    # a motion that fails on the way to a target (not to the part where it lies) names nothing out of reach
    skill = MoveTo(fresh).begin(down(2.0, -0.2, 0.1), "far away")
    assert skill.tick() == FAILURE and "out_of_reach" not in skill.failure.evidence
