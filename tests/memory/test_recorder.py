"""The trace recorder: one run -> one trace in the episodic memory, shaped as the expectation plugins look it up.

Fast tests run the letters and magnetic-attach plans on the fake world (symbolic, no objects); the slow ones record
the nominal demonstrations of A, H and magnetic attach in the pybullet simulator and check the issue-5 "Done when":
a recorded nominal A followed by a run with a substituted block raises a grid-map mismatch at the bar's step, the
magnetic-attach variant raises a keypoint mismatch, and a nominal rerun raises none.
"""

from __future__ import annotations

import math

import pytest
from py_trees.common import Status

from bt_meta.bt.context import RunContext
from bt_meta.htn import load_task_file
from bt_meta.memory import EpisodicMemory, ObjectState
from bt_meta.memory.recorder import RecorderError, TraceRecorder, object_states_of, root_task_name
from bt_meta.plugins import create_plugin_host
from bt_meta.resources import trees_dir
from bt_meta.testing import TreeHarness

LETTERS = trees_dir() / "letters.yaml"
MAGNETIC = trees_dir() / "magnetic_attach.yaml"


@pytest.fixture
def memory(tmp_path):
    with EpisodicMemory.open(tmp_path / "memory.sqlite") as opened:
        yield opened


def fake_run(path, problem: str, recorder: TraceRecorder, *, faults=(), limit: int = 500) -> Status:
    host = create_plugin_host(entry_points=False, plugins=[("recorder", recorder)])
    harness = TreeHarness.from_file(path, problem, world="fake", faults=faults, plugins=host)
    try:
        status = _tick(harness, limit)
        harness.run.finish(status)
        return status
    finally:
        harness.close()


def _tick(harness: TreeHarness, limit: int) -> Status:
    status = Status.RUNNING
    while status is Status.RUNNING and harness.run.tick_count < limit:
        status = harness.tick()
    return status


# -- fast: the fake world ------------------------------------------------------------------------------------------


def test_a_successful_run_becomes_one_trace_with_parents_facts_and_edb_rows(memory):
    recorder = TraceRecorder(memory, seed=3, config={"note": "fake"})
    assert fake_run(LETTERS, "A", recorder) is Status.SUCCESS
    assert recorder.episode_id is not None and recorder.skipped is None and recorder.error is None
    trace = memory.trace(recorder.episode_id)
    episode = trace.episode
    assert (episode.task, episode.problem, episode.outcome, episode.seed) == ("draw_A", "A", "success", 3)
    assert episode.task_file.endswith("letters.yaml") and episode.config["note"] == "fake"
    assert [(s.action, s.args) for s in trace.steps] == [
        ("place", ("b0", "0", "0")), ("place", ("b1", "0", "1")), ("place", ("b2", "3", "0")),
        ("place", ("b3", "3", "1")), ("place", ("b5", "1.5", "1")), ("place", ("b4", "1.5", "2"))]
    assert [(s.parent_task, s.task_index) for s in trace.steps] == [
        ("draw_leg", 0), ("draw_leg", 1), ("draw_leg", 0), ("draw_leg", 1), ("draw_A_bar", 0), ("draw_apex", 0)]
    # two occurrences of draw_leg are told apart by their parent node
    assert trace.steps[0].parent_node == trace.steps[1].parent_node != trace.steps[2].parent_node
    assert all(s.node_id and s.outcome == "success" and s.duration is not None for s in trace.steps)
    assert ("at", "b5", "1.5", "1") in trace.steps[4].state.facts
    assert ("at", "b5", "1.5", "1") not in trace.steps[3].state.facts
    assert ("available", "b0") in trace.initial.facts
    # E_db: one row per step keyed by its action and arguments, pointing to the parent task, with what it added
    rows = memory.expectations(task="draw_A")
    assert [(x.action, x.args_pattern, x.parent_task) for x in rows] == [
        (s.action, s.args, s.parent_task) for s in trace.steps]
    assert rows[4].facts == (("at", "b5", "1.5", "1"),) and rows[4].grid_map_id is None
    # a task's expectation is its last primitive's (bubbled up by the store)
    assert [x.step_index for x in memory.expectation_of("draw_leg")] == [1, 3]
    assert [x.step_index for x in memory.expectation_of("draw_A_bar")] == [4]
    # what recall asks: the state after plan step i of the root task
    (record,) = memory.expected_states("draw_A", 4)
    assert record.step.args == ("b5", "1.5", "1")


def test_a_failed_run_is_not_stored_unless_asked(memory):
    recorder = TraceRecorder(memory)
    assert fake_run(LETTERS, "A", recorder, faults=["place(b5, 1.5, 1)=fail:physical"]) is Status.FAILURE
    assert recorder.episode_id is None and "record_failed" in recorder.skipped
    assert recorder.trace is not None and recorder.trace.episode.outcome == "failure"
    assert memory.episodes() == []

    recorder = TraceRecorder(memory, record_failed=True)
    assert fake_run(LETTERS, "A", recorder, faults=["place(b5, 1.5, 1)=fail:physical"]) is Status.FAILURE
    trace = memory.trace(recorder.episode_id)
    assert trace.episode.outcome == "failure" and len(trace.steps) == 5
    last = trace.steps[-1]
    assert (last.action, last.outcome, last.failure_kind) == ("place", "failure", "physical")
    assert trace.episode.config["failures"][0]["kind"] == "physical"
    # no E_db row for the failed step; a failed episode is never an expectation
    assert [x.step_index for x in trace.expectations] == [0, 1, 2, 3]
    assert memory.expected_states("draw_A", 0) == []


def test_without_memory_the_trace_is_kept_but_not_written():
    recorder = TraceRecorder()
    assert fake_run(MAGNETIC, "attach_only", recorder) is Status.SUCCESS
    trace = recorder.trace
    assert recorder.episode_id is None and recorder.skipped == "no memory to write to"
    assert trace.episode.task == "MagneticAttach"
    assert [s.action for s in trace.steps] == ["MoveTo", "MoveTo", "Grasp", "MoveTo", "MoveTo", "MoveTo", "Grasp",
                                               "MoveTo"]
    assert {s.parent_task for s in trace.steps} == {"PickPart", "AttachOnto"}


def test_a_given_tree_names_the_parents_and_a_step_run_again_replaces_what_it_undid(memory):
    """Events as the repair executor sends them: steps 0-2, then a backtrack to step 1 runs 1-2 again."""
    task_file = load_task_file(MAGNETIC)
    problem = task_file.problem("attach_only")
    from bt_meta.htn import plan

    tree = plan(task_file.domain, problem).tree
    primitives = [n for n in tree.walk() if n.kind == "primitive"]
    recorder = TraceRecorder(memory, tree=tree)
    run = RunContext(None, None, domain=task_file.domain, problem=problem, task_file=task_file)
    run.install()
    emit = recorder.bt_meta_trace_event
    emit({"type": "run_start", "tick": 0, "task_file": str(MAGNETIC), "problem": "attach_only", "state": []})
    for index in (0, 1, 2, 1, 2, 3):
        node = primitives[index]
        event = {"action": node.task[0], "args": list(node.task[1:]), "node_id": node.id, "step": index, "tick": 1}
        emit({"type": "step_start", **event})
        emit({"type": "step_end", **event, "status": "SUCCESS", "state": [], "failure": None})
    emit({"type": "repair", "tick": 2, "outcome": "applied",
          "attempt": {"step": 1, "proposal": {"action": "backtrack", "plugin": "pose"}}})
    emit({"type": "run_end", "tick": 3, "status": "success", "ticks": 3})
    trace = memory.trace(recorder.episode_id)
    assert [s.node_id for s in trace.steps] == [primitives[i].id for i in range(4)]
    assert [s.parent_task for s in trace.steps] == ["PickPart", "PickPart", "PickPart", "PickPart"]
    assert trace.episode.config["repairs"] == [{"outcome": "applied", "action": "backtrack", "plugin": "pose",
                                                "step": 1}]


def test_root_task_and_object_states_helpers():
    problem = load_task_file(LETTERS).problem("A")
    assert root_task_name(problem) == "draw_A"
    with pytest.raises(RecorderError, match="has no root task"):
        root_task_name(type("P", (), {"name": "empty", "tasks": []})())

    class Observed:
        def observe(self):
            return {"objects": {"cube": {"pose": [0.5, 0.0, 0.1, math.pi, 0.0, 0.0], "ap": [0.5, 0.0, 0.05],
                                         "an": [0.0, 0.0, 1.0]},
                                "unposed": {"colour": "red"}}}

    (cube,) = object_states_of(Observed())
    assert isinstance(cube, ObjectState) and cube.name == "cube"
    assert cube.an == pytest.approx((0.0, 0.0, -1.0))  # base +z seen from an object turned upside down
    assert cube.an_base == pytest.approx((0.0, 0.0, 1.0))
    assert object_states_of(object()) == ()


def test_a_run_that_never_started_records_nothing(memory):
    recorder = TraceRecorder(memory)
    recorder.bt_meta_trace_event({"type": "step_end", "tick": 1, "action": "x", "args": [], "status": "SUCCESS"})
    recorder.bt_meta_trace_event({"type": "run_end", "tick": 1, "status": "SUCCESS"})
    assert recorder.trace is None and memory.episodes() == []


# -- slow: the simulator -------------------------------------------------------------------------------------------


def sim_run(path, problem: str, *, variant: str | None = None, plugins=(), memory=None, limit: int = 3000):
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    with quiet_stdout():
        world = SimWorld.from_task_file(path, problem, variant=variant, seed=0)
    try:
        host = create_plugin_host(entry_points=False, plugins=list(plugins))
        harness = TreeHarness.from_file(path, problem, world=world, plugins=host)
        if memory is not None:
            harness.run.memory = memory
        status = _tick(harness, limit)
        harness.run.finish(status)
        failures = list(harness.run.failures)
        harness.close()
        return status, failures
    finally:
        world.close()


@pytest.fixture(scope="module")
def demonstrations(tmp_path_factory):
    """Nominal A, H and magnetic attach recorded in the simulator into one memory."""
    memory = EpisodicMemory.open(tmp_path_factory.mktemp("demonstrations") / "memory.sqlite")
    ids = {}
    for path, problem in ((LETTERS, "A"), (LETTERS, "H"), (MAGNETIC, "nominal")):
        recorder = TraceRecorder(memory)
        status, failures = sim_run(path, problem, plugins=[("recorder", recorder)])
        assert status is Status.SUCCESS and failures == [], failures
        ids[problem] = recorder.episode_id
    yield memory, ids
    memory.close()


@pytest.mark.slow
def test_recorded_letters_carry_object_states_and_the_placed_blocks_grid_maps(demonstrations):
    memory, ids = demonstrations
    a = memory.trace(ids["A"])
    assert (a.episode.task, a.episode.variant, a.episode.seed) == ("draw_A", "nominal", 0)
    assert len(a.steps) == 6 and {o.name for o in a.initial.objects} == {"b0", "b1", "b2", "b3", "b4", "b5"}
    for step in a.steps:
        (grid,) = step.state.grid_maps  # the placed block's map only
        assert grid.object_name == step.args[0] and grid.occupancy.shape == (6, 6) and grid.image is not None
        assert {o.name for o in step.state.objects} == {"b0", "b1", "b2", "b3", "b4", "b5"}
    bar = a.steps[4]
    assert (bar.parent_task, bar.state.grid_maps[0].shape, bar.state.grid_maps[0].colour) == ("draw_A_bar", "1x2",
                                                                                              "blue")
    # the bar lies where the plan put it: cell (1.5, 1) of the letter, 6.1 cm cells from (0.55, 0.10)
    b5 = bar.state.object("b5")
    assert b5.pose[0] == pytest.approx(0.55 + 0.061, abs=0.005) and b5.pose[1] == pytest.approx(0.10 - 1.5 * 0.061,
                                                                                              abs=0.005)
    assert int(bar.state.grid_maps[0].occupancy.astype(bool).sum()) > int(
        a.steps[0].state.grid_maps[0].occupancy.astype(bool).sum())
    rows = memory.expectations(task="draw_A")
    assert len(rows) == 6 and all(x.grid_map_id is not None for x in rows)
    assert memory.grid_map(rows[4].grid_map_id).shape == "1x2"
    h = memory.trace(ids["H"])
    assert h.episode.task == "draw_H" and all(len(s.state.grid_maps) == 1 for s in h.steps)
    assert [s.parent_task for s in h.steps] == ["draw_tall_leg"] * 6 + ["draw_H_bar"] * 2
    assert [s.state.grid_maps[0].shape for s in h.steps] == ["1x1"] * 8  # H's bar: two 1x1 blocks


@pytest.mark.slow
def test_recorded_magnetic_attach_carries_ap_and_an(demonstrations):
    memory, ids = demonstrations
    trace = memory.trace(ids["nominal"])
    assert trace.episode.task == "AttachAndVerify" and len(trace.steps) == 13
    # no step names a part (pose symbols only), but the parts a step moved are watched: the active part's map
    # once it is lifted, both parts' once the subassembly is lifted to staging; a grasp moves nothing
    watched = [sorted(m.object_name for m in s.state.grid_maps) for s in trace.steps]
    assert ["active"] in watched and ["active", "reference"] in watched
    assert all(w == [] for s, w in zip(trace.steps, watched, strict=True) if s.action == "Grasp")
    after_attach = trace.steps[7].state  # MoveTo(joint_above) closing AttachOnto
    assert trace.steps[7].parent_task == "AttachOnto"
    active, reference = after_attach.object("active"), after_attach.object("reference")
    assert math.dist(active.ap, reference.ap) < 0.01  # the magnets met
    dot = sum(a * b for a, b in zip(active.an_base, reference.an_base, strict=True))
    assert dot == pytest.approx(-1.0, abs=0.05)  # R_n = 180 degrees
    assert [x.step_index for x in memory.expectation_of("AttachOnto")] == [7]


def _letters_plugins(memory=None):
    import bt_meta_plugins.camera_perception as camera_plugin
    import bt_meta_plugins.gridmap_expectations as gridmap_plugin

    expectations = gridmap_plugin if memory is None else gridmap_plugin.GridMapExpectations(memory)
    return [("camera_perception", camera_plugin), ("gridmap_expectations", expectations)]


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["A_two_1x1_same_colour", "A_two_1x1_different_colours"])
def test_recorded_nominal_a_then_a_substituted_bar_raises_a_gridmap_mismatch_at_the_bar_step(demonstrations, variant):
    memory, _ = demonstrations
    # the memory reaches the plugin as the run's memory (`bt-meta run --memory`)
    status, failures = sim_run(LETTERS, "A", variant=variant, plugins=_letters_plugins(), memory=memory)
    assert status is Status.FAILURE and len(failures) == 1
    (failure,) = failures
    assert (failure.step, failure.action, tuple(failure.args)) == (4, "place", ("b5", "1.5", "1"))
    assert failure.kind.value == "unknown_entity"
    (mismatch,) = failure.evidence["mismatches"]
    assert "b5: 4 cells differ (expected blue 1x2, seen red 1x1)" in failure.message
    assert mismatch["evidence"]["parent_task"] == "draw_A_bar" and mismatch["evidence"]["task_end"] is True


@pytest.mark.slow
def test_a_bar_of_another_colour_is_seen_only_when_colour_counts(demonstrations):
    import bt_meta_plugins.camera_perception as camera_plugin
    import bt_meta_plugins.gridmap_expectations as gridmap_plugin

    memory, _ = demonstrations
    strict = gridmap_plugin.GridMapExpectations(memory, compare_colour=True)
    status, failures = sim_run(LETTERS, "A", variant="A_bar_other_colour",
                               plugins=[("camera_perception", camera_plugin), ("gridmap_expectations", strict)])
    assert status is Status.FAILURE and [(f.step, f.kind.value) for f in failures] == [(4, "unexpected_configuration")]
    assert "expected blue 1x2, seen red 1x2" in failures[0].message


@pytest.mark.slow
def test_a_nominal_rerun_raises_no_mismatch(demonstrations):
    memory, _ = demonstrations
    status, failures = sim_run(LETTERS, "A", plugins=_letters_plugins(memory))
    assert status is Status.SUCCESS and failures == []


@pytest.mark.slow
def test_recorded_magnetic_attach_then_the_part_on_its_side_raises_a_keypoint_mismatch(demonstrations):
    import bt_meta_plugins.ground_truth_perception as truth_plugin
    import bt_meta_plugins.keypoint_expectations as keypoint_plugin

    memory, _ = demonstrations

    def plugins():
        return [("ground_truth_perception", truth_plugin),
                ("keypoint_expectations", keypoint_plugin.KeypointExpectations(memory))]

    status, failures = sim_run(MAGNETIC, "nominal", variant="active_on_side", plugins=plugins())
    assert status is Status.FAILURE
    # keypoints are checked at task ends by default: the first is the end of PickPart, step 3
    assert failures[0].step == 3 and failures[0].kind.value == "unexpected_configuration"
    assert failures[0].evidence["mismatches"][0]["kind"] == "keypoint"
    assert "R_n 90.0 deg, expected 180.0 deg" in failures[0].message
    status, failures = sim_run(MAGNETIC, "nominal", plugins=plugins())
    assert status is Status.SUCCESS and failures == []



def test_grid_maps_sent_with_the_step_end_event_are_used_for_the_named_blocks(memory):
    """A driver that sends the step's observations spares the recorder its own camera frame."""
    from types import SimpleNamespace

    import numpy as np

    from bt_meta.memory import GridMap

    def no_camera(*_):
        raise AssertionError("the recorder looked with its own camera")

    sim = SimpleNamespace(object_names=lambda: ["bar", "b0"], object_states=dict)
    world = SimpleNamespace(sim=sim, object_name=lambda symbol: {"b5": "bar", "b0": "b0"}[symbol], variant="v1")
    task_file = load_task_file(LETTERS)
    recorder = TraceRecorder(memory, camera=SimpleNamespace(look=no_camera, object_grid_maps=no_camera))
    problem = task_file.problem("A")
    run = RunContext(world, None, domain=task_file.domain, problem=problem, task_file=task_file, state=problem.state)
    run.install()
    grid = GridMap(np.eye(6, dtype=np.uint8), colour="blue", shape="1x2", centroid=(0.6, 0.0))
    emit = recorder.bt_meta_trace_event
    emit({"type": "run_start", "tick": 0, "task_file": str(LETTERS), "problem": "A", "state": []})
    emit({"type": "step_end", "tick": 1, "action": "place", "args": ["b5", "1.5", "1"], "node_id": "n8", "step": 0,
          "status": "SUCCESS", "state": [], "failure": None,
          "observations": {"object_gridmaps": {"bar": grid, "b0": grid}}})
    emit({"type": "run_end", "tick": 1, "status": "SUCCESS", "ticks": 1})
    trace = memory.trace(recorder.episode_id)
    (stored,) = trace.steps[0].state.grid_maps  # b5's map only: "1.5" and "1" name no object
    assert stored.object_name == "bar" and stored.shape == "1x2" and np.array_equal(stored.occupancy, np.eye(6))
    assert trace.episode.variant == "v1" and trace.steps[0].parent_task == "draw_A_bar"
    (row,) = trace.expectations
    assert row.grid_map_index == 0 and row.parent_task == "draw_A_bar"
