"""The letters' re-orientation skill (the place skill in mode ``turn``) on the shipped letter scene, in the real
simulator: a block on its side stands on its base after one turn where it lies, an upside-down one after two; the
campaign labeller's check of that turn (``turned_pose``) agrees it is reachable (slow)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.htn import load_task_file
from bt_meta.resources import trees_dir
from bt_meta.world.base import RUNNING
from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout
from bt_meta.world.skills import Place
from bt_meta.world.skills.place import top_down, turned_pose

pytestmark = pytest.mark.slow


def run_to_end(skill: Place, args: list[str]) -> str:
    skill.start(args)
    for _ in range(800):
        status = skill.tick()
        if status != RUNNING:
            return status
    raise AssertionError(f"{skill.name}{args} still running")


def tipped(block: str, roll: float, pitch: float) -> tuple[SimWorld, float, float]:
    """The shipped letter A scene with ``block`` laid on another face where it stood (degrees), settled; and
    where it lies (x, y). The caller closes the world."""
    task_file = load_task_file(trees_dir() / "letters.yaml")
    with quiet_stdout():
        world = SimWorld(task_file.domain, task_file.problem("A"), load_grounding("letters"))
    try:
        sim = world.sim
        x, y = sim.object_transform(block)[:2, 3]
        sim.move_object(block, sim.resting_pose(sim.object_model(block),
                                                (x, y, 0.0, math.radians(roll), math.radians(pitch), 0.0)))
        sim.settle(60)
        world.sync_collision()
    except BaseException:
        world.close()
        raise
    return world, x, y


def turn(world: SimWorld, block: str) -> str:
    skill = Place(world)
    skill.spec = {"mode": "turn"}
    return run_to_end(skill, [block])


@pytest.mark.parametrize(("roll", "pitch", "turns"), [(90.0, 0.0, 1), (0.0, -90.0, 1), (180.0, 0.0, 2)])
def test_a_block_on_another_face_stands_on_its_base_after_its_turns(roll, pitch, turns):
    world, x, y = tipped("b3", roll, pitch)
    try:
        sim = world.sim
        transform = sim.object_transform("b3")
        grasp = top_down(transform[0, 3], transform[1, 3], world.object_top("b3") + 0.004, math.pi)
        lifted = grasp.copy()
        lifted[2, 3] += 0.08
        assert turned_pose(world, "b3", "right", lifted, np.linalg.inv(grasp) @ transform)[1]
        for k in range(turns):
            assert sim.object_transform("b3")[2, 2] < math.cos(math.radians(20.0)), k  # not yet standing
            assert turn(world, "b3") == "SUCCESS"
            assert sim.held("right") is None
        assert sim.object_transform("b3")[2, 2] > math.cos(math.radians(10.0))
        assert np.linalg.norm(sim.object_transform("b3")[:2, 3] - (x, y)) < 0.05  # where it lay
    finally:
        world.close()


def test_a_block_a_failed_place_left_in_the_gripper_is_turned_from_where_it_was_picked():
    """b1 on its side (letters_A s0 0040): place picks it top-down and tilts the wrist to carry it upright; the
    wrist cannot reach down at the cell so (reachability, the block still held). The turn takes it back over where
    it was picked and turns it there: it ends standing on its base near where it lay, and is placed on its cell.
    Carried tilted, b1 keeps clear of b2 beside it (it grazed it and tipped it over before the carry kept a
    clearance)."""
    world, x, y = tipped("b1", 0.0, 90.0)
    try:
        sim = world.sim
        before = {n: sim.object_transform(n).copy() for n in sim.object_names() if n != "b1"}
        place = world.skill("place")
        status = run_to_end(place, ["b1", "0", "1"])
        assert status == "FAILURE" and place.failure.kind == "reachability", place.failure
        assert sim.held("right") == "b1"
        for name, pose in before.items():
            now = sim.object_transform(name)
            assert np.linalg.norm(now[:3, 3] - pose[:3, 3]) < 0.005 and now[2, 2] > math.cos(math.radians(5.0)), name
        others = {n: sim.object_transform(n)[:3, 3].copy() for n in sim.object_names() if n != "b1"}
        assert turn(world, "b1") == "SUCCESS"
        assert sim.held("right") is None
        approach = sim.link_transform(world.end_effector("right"))[:3, 2]
        assert approach[2] < -0.99  # the wrist left top-down: the next pick does not sweep the blocks beside it
        assert sim.object_transform("b1")[2, 2] > math.cos(math.radians(10.0))
        assert np.linalg.norm(sim.object_transform("b1")[:2, 3] - (x, y)) < 0.05
        place = world.skill("place")
        status = run_to_end(place, ["b1", "0", "1"])
        assert status == "SUCCESS", place.failure
        moved = {n: float(np.linalg.norm(sim.object_transform(n)[:3, 3] - p)) for n, p in others.items()}
        assert max(moved.values()) < 0.005, moved
    finally:
        world.close()
