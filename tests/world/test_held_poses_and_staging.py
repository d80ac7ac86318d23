"""Held-part poses relative to another object (``held:OBJECT:x:y:z:r:p:y``) and the staging verification, on the
magnetic attach scene in the simulator: a held pose follows its object when that object has moved; a part lifted
off the table without being joined to what is held does not pass the staging verification."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.htn import load_task_file
from bt_meta.resources import trees_dir
from bt_meta.world.base import FAILURE, RUNNING, SUCCESS
from bt_meta.world.simulation.objects import AttachmentFeature, Box, ObjectModel
from bt_meta.world.simulation.sim_world import (
    SimWorld,
    held_pose_symbol,
    load_grounding,
    parse_held_pose_symbol,
    quiet_stdout,
)
from bt_meta.world.skills import Grasp, MoveTo

pytestmark = pytest.mark.slow


def run(skill, max_ticks: int = 300) -> str:
    for _ in range(max_ticks):
        status = skill.tick()
        if status != RUNNING:
            return status
    raise AssertionError(f"{skill.name} still running after {max_ticks} ticks")


@pytest.fixture
def world():
    task_file = load_task_file(trees_dir() / "magnetic_attach.yaml")
    with quiet_stdout():
        w = SimWorld(task_file.domain, task_file.problem("nominal"), load_grounding("magnetic_attach"))
    yield w
    w.close()


def pick_active(world) -> None:
    for symbol in ("active_above", "active_grasp"):
        move = MoveTo(world)
        move.start([symbol])
        assert run(move) == SUCCESS
    assert run(Grasp(world).begin("active", release=False)) == SUCCESS
    move = MoveTo(world)
    move.start(["active_above"])
    assert run(move) == SUCCESS


def test_held_pose_symbols_round_trip_and_refuse_what_they_cannot_name():
    symbol = held_pose_symbol("reference_part", [0.001, -0.002, 0.05, 0.0, 0.0, 1.5708])
    assert symbol == "held:reference_part:0.001:-0.002:0.05:0:0:1.5708"
    assert parse_held_pose_symbol(symbol) == ("reference_part", [0.001, -0.002, 0.05, 0.0, 0.0, 1.5708])
    for other in ("pose:0:0:0:0:0:0", "held::0:0:0:0:0:0", "held:ref:0:0:0", "held:ref:a:0:0:0:0:0"):
        assert parse_held_pose_symbol(other) is None
    with pytest.raises(Exception, match="without ':'"):
        held_pose_symbol("a:b", [0, 0, 0, 0, 0, 0])


def test_a_held_pose_puts_the_held_part_relative_to_the_reference_where_the_reference_is_now(world):
    sim = world.sim
    x, y, z, roll, pitch, yaw = sim.object_pose("reference")
    sim.move_object("reference", (x + 0.02, y - 0.015, z, roll, pitch, yaw))  # moved after the pose was learned
    world.advance(2)
    pick_active(world)
    relative = (0.0, 0.0, 0.12, 0.0, 0.0, 0.3)
    symbol = held_pose_symbol("reference_part", relative)
    assert world.register_pose(symbol) and ("pose", symbol) in world.symbolic_state()
    move = MoveTo(world)
    move.start([symbol])
    assert run(move) == SUCCESS
    placed = np.linalg.inv(sim.object_transform("reference")) @ sim.object_transform("active")
    assert placed[:3, 3] == pytest.approx(relative[:3], abs=0.004)
    assert math.atan2(placed[1, 0], placed[0, 0]) == pytest.approx(relative[5], abs=0.03)


def test_a_part_lifted_without_being_joined_to_the_held_one_fails_the_staging_verification(world):
    """The reference stands on a pedestal (off the table) while the gripper holds the active part: both are off the
    table at the staging pose, but nothing joins them -- the subassembly is only what is held and joined to it."""
    sim = world.sim
    x, y, _, roll, pitch, yaw = sim.object_pose("reference")
    height = 0.05
    pedestal = ObjectModel(type="pedestal", colour="red", parts=(Box((0.08, 0.08, height)),), mass=0.0,
                           features=(AttachmentFeature("top", (0, 0, height / 2), (0, 0, 1)),), primary="top")
    sim.move_object("reference", (x, y - 0.3, 0.0, roll, pitch, yaw))  # out of the way while the pedestal appears
    staging = world.ground_pose("staging")
    px, py = staging[0, 3], staging[1, 3] + 0.15  # beside where the subassembly will hang, not under it
    sim.spawn("stand", pedestal, [px, py, 0.0, 0.0, 0.0, 0.0], on_table=True)
    rest = sim.resting_pose(sim.object_model("reference"), (px, py, 0.0, 0.0, 0.0, 0.0))
    sim.move_object("reference", (rest[0], rest[1], rest[2] + height, *rest[3:]))
    world.advance(5)
    assert world.object_lowest("reference") - sim.table.top_z > 0.04
    pick_active(world)
    move = MoveTo(world)
    move.start(["staging"])
    assert run(move) == FAILURE
    assert move.failure.kind == "verification"
    evidence = move.failure.evidence
    assert evidence["left_on_table"] == [] and evidence["not_joined"] == ["reference"]
    assert evidence["held"] == "active" and "without being joined" in move.failure.message
