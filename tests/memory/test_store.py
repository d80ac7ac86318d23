"""The store writes whole traces and reads back every field; bad files and bad traces fail clearly."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from bt_meta.errors import BtMetaError
from bt_meta.memory import (
    Episode,
    EpisodicMemory,
    Expectation,
    GridMap,
    MemoryStoreError,
    ObjectState,
    State,
    Step,
    Trace,
    TraceError,
)
from bt_meta.memory.trace import trace_from_dict, trace_to_dict


@pytest.fixture
def memory(tmp_path):
    with EpisodicMemory.open(tmp_path / "memory.sqlite") as opened:
        yield opened


def test_round_trip_of_every_field(memory, make_trace):
    written = make_trace(3, steps=6, objects=3, parent_tasks=("pick", "place"))
    episode_id = memory.write(written)
    read = memory.trace(episode_id)
    assert read == written
    assert read.episode.id == episode_id
    # Field by field, so that a broken __eq__ could not hide a loss.
    assert read.episode.config == {"camera": "hand", "thresholds": [0.1, 0.2], "seed": 3}
    assert read.episode.variant is None and read.episode.seed == 3
    assert read.initial.facts == (("gripper", "open"),)
    for got, want in zip(read.steps, written.steps, strict=True):
        assert (got.index, got.action, got.args, got.node_id, got.parent_task) == (
            want.index,
            want.action,
            want.args,
            want.node_id,
            want.parent_task,
        )
        assert got.state.facts == want.state.facts
        assert got.outcome == want.outcome and got.failure_kind == want.failure_kind
        assert got.duration == want.duration
        for got_object, want_object in zip(got.state.objects, want.state.objects, strict=True):
            assert got_object.pose == want_object.pose  # exact: REAL holds a float64
            assert got_object.ap == want_object.ap and got_object.an == want_object.an
        (got_map,) = got.state.grid_maps
        (want_map,) = want.state.grid_maps
        assert np.array_equal(got_map.occupancy, want_map.occupancy) and got_map.occupancy.shape == (6, 6)
        assert np.array_equal(got_map.image_array(), want_map.image_array())
        assert (got_map.colour, got_map.shape, got_map.centroid, got_map.object_name) == (
            want_map.colour,
            want_map.shape,
            want_map.centroid,
            want_map.object_name,
        )
        assert got_map.id is not None
    assert [x.args_pattern for x in read.expectations] == [x.args_pattern for x in written.expectations]
    assert all(x.grid_map_id is not None and x.episode_id == episode_id for x in read.expectations)
    # task_index counts steps within each run of a parent task: pick 0,1,2 then place 0,1,2.
    assert [s.task_index for s in read.steps] == [0, 1, 2, 0, 1, 2]


def test_failure_outcomes_and_missing_optionals_round_trip(memory):
    trace = Trace(
        episode=Episode(task="MagneticAttach", task_file="t.yaml", problem="p", started=1.0, outcome="failure"),
        steps=(
            Step(0, "MoveTo", args=([0.1, 0.2, 0.3, 0.0, 3.14, 0.0],)),
            Step(1, "Grasp", outcome="failure", failure_kind="physical"),
        ),
    )
    read = memory.trace(memory.write(trace))
    assert read == trace
    assert read.episode.finished is None and read.episode.config == {}
    assert read.steps[0].args == ([0.1, 0.2, 0.3, 0.0, 3.14, 0.0],)
    assert read.steps[1].failure_kind == "physical"


def test_nested_tuples_are_normalised_so_round_trips_compare_equal(memory):
    step = Step(0, "MoveTo", args=((1, 2), {"frame": ("base", 1)}), state=State(facts=(("at", ("x", 1)),)))
    trace = Trace(Episode("t", "f", "p", 1.0, "success"), steps=(step,))
    assert step.args == ([1, 2], {"frame": ["base", 1]})
    assert memory.trace(memory.write(trace)) == trace


def test_grid_map_image_png_bytes_and_arrays(memory):
    crop = np.arange(36 * 36 * 3, dtype=np.uint32).astype(np.uint8).reshape(36, 36, 3)
    from_array = GridMap(np.eye(6, dtype=bool), image=crop)
    from_png = GridMap(np.eye(6, dtype=np.uint8), image=from_array.image)
    assert from_array == from_png
    assert np.array_equal(from_png.image_array(), crop)
    trace = Trace(Episode("t", "f", "p", 1.0, "success"), initial=State(grid_maps=(from_png,)))
    assert np.array_equal(memory.trace(memory.write(trace)).initial.grid_maps[0].image_array(), crop)
    with pytest.raises(TraceError, match="not a PNG"):
        GridMap(np.zeros((6, 6), dtype=np.uint8), image=b"JFIF not png")


def test_bad_traces_are_refused_before_writing(memory):
    with pytest.raises(TraceError, match="expected 6 numbers, got 3"):
        ObjectState("b0", (1, 2, 3))
    with pytest.raises(TraceError, match="non-finite"):
        ObjectState("b0", (1, 2, 3, 4, 5, float("nan")))
    with pytest.raises(TraceError, match="outcome 'ok' is not one of"):
        Episode("t", "f", "p", 1.0, "ok")
    with pytest.raises(TraceError, match=r"has index 2; steps are 0\.\.n-1"):
        Trace(Episode("t", "f", "p", 1.0, "success"), steps=(Step(0, "a"), Step(2, "b")))
    with pytest.raises(TraceError, match="refers to step 5"):
        Trace(Episode("t", "f", "p", 1.0, "success"), steps=(Step(0, "a"),), expectations=(Expectation(5, "a"),))
    with pytest.raises(TraceError, match="refers to grid-map 0 of step 0, which has 0"):
        Trace(
            Episode("t", "f", "p", 1.0, "success"),
            steps=(Step(0, "a"),),
            expectations=(Expectation(0, "a", grid_map_index=0),),
        )
    with pytest.raises(TraceError, match="is not a JSON value"):
        Step(0, "a", args=(object(),))
    with pytest.raises(TraceError, match="does not start with a predicate name"):
        State(facts=((1, "b0"),))
    with pytest.raises(TraceError, match="object names repeat"):
        State(objects=(ObjectState("b0", [0] * 6), ObjectState("b0", [0] * 6)))
    with pytest.raises(TraceError, match="a successful step has no failure kind"):
        Step(0, "a", failure_kind="physical")
    with pytest.raises(TraceError, match="occupancy must be a non-empty 2-D array"):
        GridMap(np.zeros(36, dtype=np.uint8))
    assert issubclass(TraceError, BtMetaError)
    assert memory.episodes() == []


def test_failed_write_leaves_nothing_and_the_store_usable(memory, make_trace, monkeypatch):
    memory.write(make_trace(1))
    # Make the expectations insert fail half-way through the transaction with a real SQLite error.
    memory._connection.execute(
        "CREATE TRIGGER refuse BEFORE INSERT ON expectations BEGIN SELECT RAISE(ABORT, 'no'); END"
    )
    with pytest.raises(MemoryStoreError, match="writing a trace failed, nothing was stored"):
        memory.write(make_trace(2))
    assert [s.episode.seed for s in memory.episodes()] == [1]
    for table in ("steps", "object_states", "grid_maps"):
        count = memory._connection.execute(f"SELECT count(*) FROM {table} WHERE episode_id != 1").fetchone()[0]
        assert count == 0, table
    memory._connection.execute("DROP TRIGGER refuse")
    memory.write(make_trace(3))
    assert memory.check() == [] and memory.integrity_check() == "ok"


def test_pragmas_wal_foreign_keys_busy_timeout(memory):
    connection = memory._connection
    assert connection.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert connection.execute("PRAGMA foreign_keys").fetchone()[0] == 1
    assert connection.execute("PRAGMA busy_timeout").fetchone()[0] >= 1000


def test_reopen_and_second_connection_see_the_same_traces(tmp_path, make_trace):
    path = tmp_path / "memory.sqlite"
    with EpisodicMemory.open(path) as first:
        ids = [first.write(make_trace(seed)) for seed in range(3)]
        with EpisodicMemory.open(path) as second:
            assert [second.trace(i) for i in ids] == [make_trace(seed) for seed in range(3)]
    with EpisodicMemory.open(path, readonly=True) as readonly:
        assert len(readonly.episodes()) == 3
        with pytest.raises(MemoryStoreError, match="opened read-only"):
            readonly.write(make_trace(4))


def test_export_format_round_trips(memory, make_trace):
    written = make_trace(5, steps=3)
    read = memory.trace(memory.write(written))
    assert trace_from_dict(trace_to_dict(read)) == written
    with pytest.raises(TraceError, match="trace document is malformed"):
        trace_from_dict({"steps": []})


def test_missing_memory_is_not_created_when_only_reading(tmp_path):
    path = tmp_path / "nowhere" / "memory.sqlite"
    with pytest.raises(MemoryStoreError, match="no episodic memory here") as raised:
        EpisodicMemory.open(path, create=False)
    assert str(path) in str(raised.value)
    assert not path.parent.exists()


def test_unknown_episode_is_a_clear_error(memory):
    with pytest.raises(MemoryStoreError, match="no episode 42"):
        memory.trace(42)


def test_foreign_key_cascade_is_declared(memory, make_trace):
    episode_id = memory.write(make_trace(1))
    with pytest.raises(sqlite3.IntegrityError):
        memory._connection.execute(
            "INSERT INTO steps (episode_id, step_index, action, args, facts, outcome, object_count, grid_map_count)"
            " VALUES (?, 0, 'x', '[]', '[]', 'success', 0, 0)",
            (episode_id + 100,),
        )


def test_attachment_normal_frames_agree_with_the_world_convention():
    from bt_meta.world.simulation.objects import rpy_to_matrix

    pose = (0.6, -0.2, 0.05, 0.3, -1.1, 2.4)
    state = ObjectState("housing", pose, (0.61, -0.2, 0.08), (0.0, 0.0, 1.0))
    assert np.allclose(state.rotation(), rpy_to_matrix(*pose[3:]))
    assert np.allclose(state.an_base, rpy_to_matrix(*pose[3:])[:, 2])
    rebuilt = ObjectState.from_base_normal("housing", pose, state.ap, state.an_base)
    assert np.allclose(rebuilt.an, (0.0, 0.0, 1.0))


def test_concurrent_writers_wait_for_each_other(tmp_path, make_trace):
    import threading

    path = tmp_path / "memory.sqlite"
    EpisodicMemory.open(path).close()
    traces = [make_trace(seed, steps=30, image=False) for seed in range(24)]
    errors: list[BaseException] = []

    def writer(part: int) -> None:
        try:
            with EpisodicMemory.open(path) as memory:
                for trace in traces[part::3]:
                    memory.write(trace)
        except BaseException as error:  # reported below: a thread's exception would otherwise vanish
            errors.append(error)

    threads = [threading.Thread(target=writer, args=(part,)) for part in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    with EpisodicMemory.open(path) as memory:
        assert sorted(s.episode.seed for s in memory.episodes()) == list(range(24))
        assert memory.check() == [] and memory.integrity_check() == "ok"
