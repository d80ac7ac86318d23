"""The meta-reasoner's queries: expected states, successful states, last traces, P_a, E_db and grid-map NN."""

from __future__ import annotations

import numpy as np
import pytest

from bt_meta.memory import (
    Episode,
    EpisodicMemory,
    Expectation,
    GridMap,
    State,
    Step,
    Trace,
    grid_distance,
)


@pytest.fixture
def memory(tmp_path):
    with EpisodicMemory.open(tmp_path / "memory.sqlite") as opened:
        yield opened


@pytest.fixture
def filled(memory, make_trace):
    """Three successful draw_A runs (started 1, 3, 4), one failed (started 2), one draw_H (started 5)."""
    ids = {
        "a1": memory.write(make_trace(1, started=1.0)),
        "a_fail": memory.write(make_trace(2, started=2.0, outcome="failure")),
        "a3": memory.write(make_trace(3, started=3.0)),
        "a4": memory.write(make_trace(4, started=4.0, parent_tasks=("approach", "attach"))),
        "h": memory.write(make_trace(5, task="draw_H", started=5.0)),
    }
    return memory, ids


def test_expected_states_after_step_i_of_a_task(filled, make_trace):
    memory, ids = filled
    records = memory.expected_states("draw_A", 2)
    assert [r.episode_id for r in records] == [ids["a4"], ids["a3"], ids["a1"]]  # newest first, no failure
    assert all(r.task == "draw_A" and r.step.index == 2 for r in records)
    assert records[1].step == make_trace(3, started=3.0).steps[2]
    assert [r.episode_id for r in memory.expected_states("draw_A", 2, last=2)] == [ids["a4"], ids["a3"]]
    assert memory.expected_states("draw_A", 99) == []
    assert memory.expected_states("draw_Z", 0) == []


def test_expected_states_by_parent_task_count_within_the_task(filled, make_trace):
    memory, ids = filled
    # a4 has approach (steps 0, 1) then attach (steps 2, 3): attach's task-step 1 is the episode's step 3.
    (record,) = memory.expected_states("attach", 1, by="parent", with_before=True)
    assert record.episode_id == ids["a4"] and record.step.index == 3 and record.step.task_index == 1
    assert record.before == make_trace(4, started=4.0, parent_tasks=("approach", "attach")).steps[2].state
    with pytest.raises(ValueError, match="by must be"):
        memory.expected_states("attach", 1, by="nonsense")


def test_states_that_led_to_success_of_an_action(filled, make_trace):
    memory, ids = filled
    records = memory.successful_states("place")
    # 3 successful draw_A episodes and one draw_H, 4 steps each; the failed episode contributes nothing.
    assert len(records) == 16
    assert ids["a_fail"] not in {r.episode_id for r in records}
    first_steps = [r for r in records if r.step.index == 0]
    assert len(first_steps) == 4
    for record in first_steps:  # step 0 started from the episode's initial state
        assert record.before.objects == memory.trace(record.episode_id).initial.objects
        assert record.before.facts == (("gripper", "open"),)
    later = next(r for r in records if r.episode_id == ids["a3"] and r.step.index == 2)
    assert later.before == make_trace(3, started=3.0).steps[1].state
    b1 = memory.successful_states("place", args=("b1", None, "?y"))
    assert b1 and all(r.step.args[0] == "b1" for r in b1)
    assert len(memory.successful_states("place", last=5)) == 5
    assert memory.successful_states("weld") == []


def test_last_n_traces_of_a_task(filled, make_trace):
    memory, ids = filled
    traces = memory.last_traces("draw_A", 2)
    assert [t.episode.id for t in traces] == [ids["a4"], ids["a3"]]
    assert traces[1] == make_trace(3, started=3.0)
    everything = memory.last_traces("draw_A", 10, outcome=None)
    assert [t.episode.id for t in everything] == [ids["a4"], ids["a3"], ids["a_fail"], ids["a1"]]
    assert [t.episode.outcome for t in memory.last_traces("draw_A", 10, outcome="failure")] == ["failure"]


def test_p_a_holds_the_successful_plan_executions(filled):
    memory, ids = filled
    steps = memory.plan_executions("draw_A")
    assert sorted({s.episode_id for s in steps}) == sorted([ids["a1"], ids["a3"], ids["a4"]])
    assert [s.step_index for s in steps if s.episode_id == ids["a1"]] == [0, 1, 2, 3]
    assert steps[0].facts[0][0] == "placed" and steps[0].action == "place"
    assert len(memory.plan_executions()) == 16


def test_e_db_expectations_and_bubbling_to_the_parent_task(filled):
    memory, ids = filled
    everything = memory.expectations()
    assert len(everything) == 20
    assert all(x.grid_map_id is not None for x in everything)
    attach = memory.expectations(parent_task="attach")
    assert [(x.episode_id, x.step_index) for x in attach] == [(ids["a4"], 2), (ids["a4"], 3)]
    assert len(memory.expectations(task="draw_H")) == 4
    assert memory.expectations(action="weld") == []
    # A task's expectation is its last primitive's: step 3 for attach, step 1 for approach.
    assert [x.step_index for x in memory.expectation_of("attach")] == [3]
    assert [x.step_index for x in memory.expectation_of("approach")] == [1]
    # place_block runs once per other episode (all four steps), so its last step 3 of each of four episodes.
    assert sorted(x.step_index for x in memory.expectation_of("place_block")) == [3, 3, 3, 3]
    grid = memory.grid_map(attach[0].grid_map_id)
    assert grid.id == attach[0].grid_map_id and grid.occupancy.shape == (6, 6)


def test_nearest_grid_maps_agree_with_brute_force(memory, make_trace):
    for seed in range(40):
        memory.write(make_trace(seed, steps=5, image=False))
    stored = [(x, memory.grid_map(x.grid_map_id)) for x in memory.expectations()]
    rng = np.random.default_rng(99)
    for _ in range(25):
        query = (rng.random((6, 6)) < 0.4).astype(np.uint8)
        for rotations in (True, False):
            matches = memory.nearest_grid_maps(query, 7, rotations=rotations, successful_only=False)
            expected = sorted(
                (grid_distance(query, grid.occupancy, rotations=rotations)[0], x.id) for x, grid in stored
            )[:7]
            assert [(m.distance, m.expectation_id) for m in matches] == expected
            for match in matches:
                target = memory.grid_map(match.grid_map_id).occupancy
                turned = np.rot90(query != 0, match.rotation)
                assert int(np.count_nonzero(turned != (target != 0))) == match.distance


def test_rotated_map_is_found_at_distance_zero_with_its_rotation(memory):
    base = np.zeros((6, 6), dtype=np.uint8)
    base[1:3, 1:5] = 1  # a 1x2 block lying along x
    base[4, 0] = 1
    trace = Trace(
        Episode("draw_A", "letters.yaml", "A", 1.0, "success"),
        steps=(Step(0, "place", ("b0", 0.5, 0.1), state=State(grid_maps=(GridMap(base, colour="red", shape="1x2"),))),),
        expectations=(Expectation(0, "place", ("b0", "?x", "?y"), "draw_A", grid_map_index=0),),
    )
    memory.write(trace)
    query = np.rot90(base, -1)  # the same form, turned a quarter clockwise
    (match,) = memory.nearest_grid_maps(query, 1)
    assert match.distance == 0 and match.rotation == 1
    assert np.array_equal(np.rot90(query, match.rotation), base)
    (unrotated,) = memory.nearest_grid_maps(query, 1, rotations=False)
    assert unrotated.distance > 0 and unrotated.rotation == 0


def test_two_1x1_blocks_match_a_1x2_by_form_where_symbols_do_not(memory):
    """Section 6.4, row 3: A's red 1x2 replaced by two 1x1; H's pair of 1x1 blocks is the grid-map match."""

    def record(task, maps):
        steps = tuple(
            Step(i, "place", (name, 0.5, 0.1 * i), parent_task=task, state=State(grid_maps=(grid,)))
            for i, (name, grid) in enumerate(maps)
        )
        expectations = tuple(
            Expectation(i, "place", (s.args[0], "?x", "?y"), task, grid_map_index=0) for i, s in enumerate(steps)
        )
        return memory.write(
            Trace(Episode(task, "letters.yaml", task, 1.0, "success"), steps, expectations=expectations)
        )

    bar = np.zeros((6, 6), dtype=np.uint8)
    bar[1:5, 2:4] = 1  # 1x2 upright
    left = np.zeros((6, 6), dtype=np.uint8)
    left[0:2, 2:4] = 1  # a 1x1
    pair = np.zeros((6, 6), dtype=np.uint8)
    pair[1:5, 2:4] = 1  # two 1x1 stacked: same form as the 1x2
    a_id = record("draw_A", [("b_red_1x2", GridMap(left, colour="blue", shape="1x1"))])
    h_id = record("draw_H", [("b_1x1_top", GridMap(pair, colour="red", shape="1x1"))])
    query = GridMap(bar, colour="red", shape="1x2")
    best = memory.nearest_grid_maps(query, 2)
    assert [m.episode_id for m in best] == [h_id, a_id]
    assert best[0].distance == 0 and best[0].shape == "1x1"  # a symbolic 1x2 match would not have found it


def test_filters_ties_and_shapes(memory):
    grid = np.zeros((6, 6), dtype=np.uint8)
    grid[0, 0] = 1

    def write(task, outcome, action="place", shape=(6, 6)):
        occupancy = np.zeros(shape, dtype=np.uint8)
        occupancy[0, 0] = 1
        step = Step(0, action, (), parent_task=task, state=State(grid_maps=(GridMap(occupancy),)))
        trace = Trace(
            Episode(task, "f", "p", 1.0, outcome),
            (step,),
            expectations=(Expectation(0, action, (), task, grid_map_index=0),),
        )
        return memory.write(trace)

    first = write("draw_A", "success")
    second = write("draw_A", "success", action="pick")
    failed = write("draw_H", "failure")
    third = write("draw_H", "success")
    other_shape = write("draw_H", "success", shape=(4, 8))
    ties = memory.nearest_grid_maps(grid, 10)
    assert [m.episode_id for m in ties] == [first, second, third]  # all distance 0: oldest first
    assert failed in [m.episode_id for m in memory.nearest_grid_maps(grid, 10, successful_only=False)]
    assert [m.episode_id for m in memory.nearest_grid_maps(grid, 10, action="pick")] == [second]
    assert [m.episode_id for m in memory.nearest_grid_maps(grid, 10, task="draw_H")] == [third]
    assert [m.episode_id for m in memory.nearest_grid_maps(grid, 10, parent_task="draw_A")] == [first, second]
    assert [m.episode_id for m in memory.nearest_grid_maps(grid, 10, exclude_episode=first)] == [second, third]
    assert memory.nearest_grid_maps(grid, 10, action="weld") == []
    assert memory.nearest_grid_maps(grid, 0) == []
    wide = np.zeros((4, 8), dtype=np.uint8)
    wide[0, 0] = 1
    (match,) = memory.nearest_grid_maps(wide, 5)
    assert match.episode_id == other_shape and match.distance == 0
    assert memory.nearest_grid_maps(np.zeros((3, 3)), 5) == []
    with pytest.raises(ValueError, match="must be 2-D"):
        memory.nearest_grid_maps(np.zeros(36), 5)


def test_nn_cache_sees_writes_from_this_and_other_connections(memory, tmp_path):
    grid = np.ones((6, 6), dtype=np.uint8)

    def trace():
        step = Step(0, "place", state=State(grid_maps=(GridMap(grid),)))
        return Trace(
            Episode("t", "f", "p", 1.0, "success"),
            (step,),
            expectations=(Expectation(0, "place", grid_map_index=0),),
        )

    assert memory.nearest_grid_maps(grid, 5) == []
    memory.write(trace())
    assert len(memory.nearest_grid_maps(grid, 5)) == 1
    with EpisodicMemory.open(memory.path) as other:
        other.write(trace())
    assert len(memory.nearest_grid_maps(grid, 5)) == 2


def test_popcount_fallback_and_multi_word_grids(memory, monkeypatch):
    from bt_meta.memory import store

    rng = np.random.default_rng(7)
    words = rng.integers(0, 2**63, (50, 3), dtype=np.uint64)
    expected = np.array([sum(bin(int(w)).count("1") for w in row) for row in words])
    assert np.array_equal(store._popcount_rows(words), expected)
    monkeypatch.delattr(np, "bitwise_count", raising=False)  # numpy < 2 has no bitwise_count
    assert np.array_equal(store._popcount_rows(words), expected)
    monkeypatch.undo()
    # 10 x 10 grids need two 64-bit words per map.
    grids = [(rng.random((10, 10)) < 0.5).astype(np.uint8) for _ in range(30)]
    steps = tuple(Step(i, "place", state=State(grid_maps=(GridMap(g),))) for i, g in enumerate(grids))
    expectations = tuple(Expectation(i, "place", grid_map_index=0) for i in range(len(grids)))
    memory.write(Trace(Episode("t", "f", "p", 1.0, "success"), steps, expectations=expectations))
    query = (rng.random((10, 10)) < 0.5).astype(np.uint8)
    matches = memory.nearest_grid_maps(query, 4)
    brute = sorted((grid_distance(query, g)[0], i) for i, g in enumerate(grids))[:4]
    assert [(m.distance, m.step_index) for m in matches] == brute


def test_consecutive_occurrences_of_a_task_are_told_apart_by_parent_node(memory):
    """Two place_block tasks in a row (nodes t1, t2): task-step indices restart, each bubbles up its own last step."""
    steps = tuple(
        Step(i, action, (block,), node_id=f"n{i}", parent_task="place_block", parent_node=node)
        for i, (action, block, node) in enumerate(
            [("pick", "b0", "t1"), ("place", "b0", "t1"), ("pick", "b1", "t2"), ("place", "b1", "t2")]
        )
    )
    expectations = tuple(Expectation(i, s.action, s.args, "place_block") for i, s in enumerate(steps))
    episode_id = memory.write(Trace(Episode("draw_H", "f", "p", 1.0, "success"), steps, expectations=expectations))
    assert [s.task_index for s in memory.trace(episode_id).steps] == [0, 1, 0, 1]
    assert [s.parent_node for s in memory.plan_executions("draw_H")] == ["t1", "t1", "t2", "t2"]
    assert [x.step_index for x in memory.expectation_of("place_block")] == [1, 3]
    assert [r.step.args for r in memory.expected_states("place_block", 1, by="parent")] == [("b0",), ("b1",)]
