"""The place skill among blocks already drawn, in the real simulator (slow): a block drawn out from between
others and one set down beside another leave their neighbours where they were; a placement that failed on the way
(the block still held) is carried on from where it is when it runs again."""

from __future__ import annotations

import numpy as np
import pytest

from bt_meta.htn import load_task_file
from bt_meta.resources import trees_dir
from bt_meta.world.base import RUNNING
from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout
from bt_meta.world.skills import Place
from bt_meta.world.skills.place import SET_DOWN

pytestmark = pytest.mark.slow


@pytest.fixture
def world():
    task_file = load_task_file(trees_dir() / "letters.yaml")
    with quiet_stdout():
        w = SimWorld(task_file.domain, task_file.problem("A"), load_grounding("letters"))
    yield w
    w.close()


def place(world: SimWorld, block: str, x: str, y: str) -> tuple[str, Place]:
    skill = Place(world)
    skill.spec = {"frame": "letter"}
    skill.start([block, x, y])
    for _ in range(1500):
        status = skill.tick()
        if status != RUNNING:
            return status, skill
    raise AssertionError(f"place({block}, {x}, {y}) still running")


def xy(world: SimWorld, block: str) -> np.ndarray:
    return world.sim.object_transform(block)[:2, 3].copy()


def phases(skill: Place) -> list[str]:
    """The phases that moved or acted (a phase with nothing to do is listed without a skill)."""
    return [p["phase"] for p in skill.info["phases"] if "skill" in p]


def test_a_block_drawn_out_from_between_others_and_set_down_beside_one_leaves_them_in_place(world):
    """A's first leg (b0 at (0, 0), b1 on it at (0, 1)) and b2 across (2, 1)-(3, 1); then b1 is moved to the foot
    (3, 0) under b2, the re-tiling's move (generated letters_A s1 0046): b1 leaves b0's side slowly, and goes down
    slowly beside b2. At full speed b0 was kicked 2 cm and b2 shoved 5 mm."""
    assert place(world, "b0", "0", "0")[0] == "SUCCESS"
    status, first = place(world, "b1", "0", "1")
    assert status == "SUCCESS" and "set down" in phases(first)  # beside b0
    assert place(world, "b5", "2.5", "1")[0] == "SUCCESS"
    b0, b5 = xy(world, "b0"), xy(world, "b5")
    status, moved = place(world, "b1", "3", "0")
    assert status == "SUCCESS", moved.info
    assert "withdraw" in phases(moved) and "set down" in phases(moved)
    assert np.linalg.norm(xy(world, "b0") - b0) < 0.002
    assert np.linalg.norm(xy(world, "b5") - b5) < 0.002
    # alone on the table nothing slows: a block picked where nothing touches it is lifted at once
    status, alone = place(world, "b4", "5", "0")
    assert status == "SUCCESS" and "withdraw" not in phases(alone) and "set down" not in phases(alone)
    assert SET_DOWN > 0


def test_a_placement_run_again_with_its_block_still_held_carries_it_from_where_it_is(world):
    sim = world.sim
    # hold b3 as a failed carry would have left it: picked, lifted, not put down
    skill = Place(world)
    skill.spec = {"frame": "letter"}
    skill.start(["b3", "5", "0"])
    while skill.info.get("phase") != "carry":
        assert skill.tick() == RUNNING
    assert sim.held("right") == "b3"
    status, again = place(world, "b3", "5", "1")
    assert status == "SUCCESS", again.info
    assert phases(again)[0] == "lift" and "grasp" not in phases(again)
    assert sim.held("right") is None
    target = np.array(world.ground_cell("letter", "5", "1")[:2])
    assert np.linalg.norm(xy(world, "b3") - target) < 0.01


def test_a_block_set_down_where_a_distractor_reaches_a_few_millimetres_in_pushes_it_aside(world):
    """A green bar reaching 3 mm into cell (0, 0): b0 goes down there and the bar is pushed away (what the
    skill's ``place_overlap`` counts as room); 11 mm in, the lowering collides with it."""
    from bt_meta.world.simulation.objects import LB, megablok
    from bt_meta.world.skills.place import place_overlap

    sim = world.sim
    cell = np.array(world.ground_cell("letter", "0", "0")[:2])
    reach = 0.003
    sim.spawn("d", megablok("1x2", "green"), (cell[0], cell[1] + LB - reach, 0, 0, 0, 0), on_table=True)
    sim.settle(60)
    world.sync_collision()
    before = xy(world, "d")
    status, skill = place(world, "b0", "0", "0")
    assert status == "SUCCESS", skill.info
    assert np.linalg.norm(xy(world, "b0") - cell) < 0.005
    assert xy(world, "d")[1] > before[1] + 0.001  # pushed aside
    assert reach < place_overlap()
    far = np.array(world.ground_cell("letter", "3", "0")[:2])
    sim.spawn("deep", megablok("1x2", "green"), (far[0], far[1] - LB + 0.011, 0, 0, 0, 0), on_table=True)
    sim.settle(60)
    world.sync_collision()
    status, skill = place(world, "b2", "3", "0")
    assert status == "FAILURE" and skill.record()["failure"]["kind"] == "collision", skill.info


def test_a_block_is_not_set_down_where_an_object_reaches_deeper_than_the_room_it_takes(world):
    """A green bar reaching 7.5 mm into cell (0, 0), deeper than ``place_overlap`` (6 mm) and lower than where the
    lowering beside others ends: the place fails before the lowering, ``collision`` with the pair, and the bar is
    where it was (generated letters_H s1 0058: 6.5 mm in, the set-down shoved it aside)."""
    from bt_meta.world.simulation.objects import LB, megablok
    from bt_meta.world.skills.place import place_overlap

    sim = world.sim
    cell = np.array(world.ground_cell("letter", "0", "0")[:2])
    reach = 0.0075
    assert reach > place_overlap()
    sim.spawn("d", megablok("1x2", "green"), (cell[0], cell[1] + LB - reach, 0, 0, 0, 0), on_table=True)
    sim.settle(60)
    world.sync_collision()
    before = xy(world, "d")
    status, skill = place(world, "b0", "0", "0")
    assert status == "FAILURE" and skill.failure.kind == "collision", skill.info
    assert skill.failure.evidence["failed_phase"] == "room" and skill.failure.evidence["objects"] == ["b0", "d"]
    assert np.linalg.norm(xy(world, "d") - before) < 0.001


def test_the_world_says_where_a_block_can_be_put_down(world):
    """``SimWorld.put_down_problem``, what a re-tiling asks before it sets a block aside: a free, reachable cell is
    fine; one another block lies on, or out of the arm's reach, is not, and the answer says why."""
    assert world.put_down_problem("b0", "letter", 5, 0) is None
    origin = np.array(world.ground_cell("letter", "0", "0")[:2])
    axes = np.column_stack([np.array(world.ground_cell("letter", *p)[:2]) - origin for p in (("1", "0"), ("0", "1"))])
    u, v = np.linalg.solve(axes, world.sim.object_transform("b1")[:2, 3] - origin)  # b1 where it lies, in the frame
    assert "b1 within 1 cm" in world.put_down_problem("b0", "letter", round(float(u), 3), round(float(v), 3))
    assert "no IK solution" in world.put_down_problem("b0", "letter", -8, 0)


def test_a_move_slower_than_nothing_or_faster_than_the_arm_is_refused(world):
    from bt_meta.world.skills import MoveTo

    for speed in (0.0, -0.5, 1.5):
        with pytest.raises(ValueError, match="speed must be in"):
            MoveTo(world, speed=speed)


def test_the_finger_pads_are_checked_against_each_objects_pose_read_once(world, monkeypatch):
    """Choosing a grasp yaw tests 108 pad points per pose against every other object: each object's pose is read
    once per yaw (not once per point), and a point is inside an object alike either way."""
    sim = world.sim
    skill = Place(world)
    skill.spec = {"frame": "letter"}
    skill.start(["b1", "0", "1"])
    reads = []
    real = sim.object_transform
    monkeypatch.setattr(sim, "object_transform", lambda name: reads.append(name) or real(name))
    counts = [skill._finger_obstruction(yaw) for yaw in (0.0, 0.5 * np.pi, 0.25 * np.pi)]
    assert len(reads) <= 3 * (len(list(sim.object_names())) + 4), len(reads)
    monkeypatch.setattr(sim, "object_transform", real)
    others = skill._others()
    b0 = real("b0")[:3, 3]
    points = [b0 + np.array([dx, dy, dz]) for dx in (-0.09, -0.02, 0.0, 0.015, 0.09)
              for dy in (-0.09, 0.0, 0.02) for dz in (-0.01, 0.0, 0.09)]
    inside = [skill._inside_others(p) for p in points]
    assert inside == [skill._inside_others(p, others=others) for p in points] and 0 < sum(inside) < len(points)
    assert all(c >= 0 for c in counts)
