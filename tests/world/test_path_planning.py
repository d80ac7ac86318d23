"""Joint-space path planning (``bt_meta.world.kinematics.path_planning``): RRT-Connect around a wall, the same path
for the same seed, ``None`` when the goal is walled off, the straight segment when nothing is in the way; and in the
real simulator, MoveTo going over a wall the straight lines run into (slow)."""

from __future__ import annotations

import itertools
import math
import textwrap

import numpy as np
import pytest

from bt_meta.world.kinematics.path_planning import PlanningStats, plan_path

LOWER, UPPER = np.array([-1.0, -1.0]), np.array([1.0, 1.0])


def wall_with_gap(gap_low: float | None):
    """Free everywhere but a wall at |x| < 0.05, open only for y in (gap_low, gap_low + 0.15)."""

    def free(q: np.ndarray) -> bool:
        if abs(q[0]) >= 0.05:
            return True
        return gap_low is not None and gap_low < q[1] < gap_low + 0.15

    return free


def dense_free(path: list[np.ndarray], free, resolution: float = 0.005) -> bool:
    for a, b in itertools.pairwise(path):
        count = max(1, math.ceil(float(np.max(np.abs(b - a))) / resolution))
        if not all(free(a + (b - a) * (k / count)) for k in range(count + 1)):
            return False
    return True


def test_a_path_goes_through_the_gap_in_a_wall_the_straight_line_hits():
    free = wall_with_gap(0.6)
    start, goal = np.array([-0.5, 0.0]), np.array([0.5, 0.0])
    stats = PlanningStats()
    path = plan_path(free, start, goal, LOWER, UPPER, resolution=0.01, iterations=2000, stats=stats)
    assert path is not None and stats.found
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert dense_free(path, free, resolution=0.01)  # every segment is free where the planner checks it
    through = [a + (b - a) * t for a, b in itertools.pairwise(path) for t in np.linspace(0, 1, 200)]
    crossing = [q for q in through if abs(q[0]) < 0.05]
    assert crossing and all(0.6 < q[1] < 0.75 for q in crossing)  # it crosses the wall's line in the gap
    assert stats.checks > 0 and stats.iterations >= 1


def test_the_same_seed_gives_the_same_path_and_another_seed_may_not():
    free = wall_with_gap(-0.3)
    start, goal = np.array([-0.6, 0.5]), np.array([0.6, 0.5])
    first = plan_path(free, start, goal, LOWER, UPPER, resolution=0.01, iterations=2000, seed=4)
    again = plan_path(free, start, goal, LOWER, UPPER, resolution=0.01, iterations=2000, seed=4)
    assert first is not None and again is not None
    assert len(first) == len(again) and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))


def test_a_goal_walled_off_has_no_path_after_the_whole_budget():
    stats = PlanningStats()
    path = plan_path(wall_with_gap(None), [-0.5, 0.0], [0.5, 0.0], LOWER, UPPER, iterations=150, stats=stats)
    assert path is None
    assert not stats.found and stats.iterations == 150 and stats.nodes > 2


def test_nothing_in_the_way_is_the_straight_segment():
    stats = PlanningStats()
    path = plan_path(lambda q: True, [0.0, 0.0], [0.5, 0.5], LOWER, UPPER, stats=stats)
    assert path is not None and len(path) == 2 and stats.iterations == 0


def test_neither_end_is_checked():
    """The arm is at the start and IK checked the goal: a start touching something (a part lifted off the table)
    still gets a path."""
    free = lambda q: not (np.linalg.norm(q - np.array([-0.5, 0.0])) < 1e-9)  # noqa: E731
    assert plan_path(free, [-0.5, 0.0], [0.5, 0.0], LOWER, UPPER) is not None


WALLED = """\
scene: walled
anchors:
  set_down_spot: [0.50, -0.28, table, 0, 0, 0]
objects:
  - {name: reference, type: magnet_reference, pose: [0.62, -0.10, table, 0, 0, 0]}
  - {name: active, type: magnet_active, pose: [0.58, -0.40, table, 0, 0, 0]}
obstacles:
  - {name: wall, shape: wall, size: [0.30, 0.02, 0.25], pose: [0.70, -0.25, table, 0, 0, 0]}
"""


@pytest.mark.slow
def test_move_to_goes_over_a_wall_the_straight_paths_run_into(tmp_path):
    from bt_meta.htn import load_task_file
    from bt_meta.resources import trees_dir
    from bt_meta.world.base import RUNNING, SUCCESS
    from bt_meta.world.simulation.objects import pose_to_matrix
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout
    from bt_meta.world.skills import MoveTo

    scene = tmp_path / "walled.yaml"
    scene.write_text(textwrap.dedent(WALLED), encoding="utf-8")
    task_file = load_task_file(trees_dir() / "magnetic_attach.yaml")
    with quiet_stdout():
        world = SimWorld(task_file.domain, task_file.problem("nominal"), load_grounding("magnetic_attach"),
                         scene=scene)
    try:
        low = world.sim.table.top_z + 0.08  # gripper frame 8 cm over the table, well under the wall's top
        for y in (-0.35, -0.13):  # one side of the wall (y = -0.25), then the other
            skill = MoveTo(world).begin(pose_to_matrix((0.70, y, low, math.pi, 0.0, math.pi)), f"y={y}")
            touched: set[str] = set()
            for _ in range(400):
                status = skill.tick()
                touched |= set(world.robot_contacts("right"))
                if status != RUNNING:
                    break
            assert status == SUCCESS, skill.record()
            assert not touched
        assert skill.info["path"] == "planned"  # the joint line, the Cartesian line and the lift all hit the wall
        assert skill.info["planner"]["found"] and skill.info["planner"]["checks"] > 0
        assert np.linalg.norm(world.sim.link_transform("right_gripper")[:3, 3] - (0.70, -0.13, low)) < 0.003
    finally:
        world.close()
