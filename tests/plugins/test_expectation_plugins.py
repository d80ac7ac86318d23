"""Grid-map and keypoint expectation plugins against a temporary episodic memory of recorded states.

A substituted block (A's 1x2 bar replaced by a 1x1) raises a grid-map mismatch at the bar's step; a misaligned
attach raises a keypoint mismatch; nominal observations raise none. The plugin modules are registered explicitly
with the plugin manager, as the ``bt_meta`` entry points will register them.
"""

from __future__ import annotations

import math
import time
from types import SimpleNamespace
from typing import Any

import bt_meta_plugins.gridmap_expectations as gridmap_plugin
import bt_meta_plugins.keypoint_expectations as keypoint_plugin
import numpy as np
import pytest
from bt_meta_plugins.camera_perception import TABLE_COLOUR

from bt_meta.bt.context import RunContext
from bt_meta.bt.expectations import Expectation, StepContext
from bt_meta.htn import State as HtnState
from bt_meta.memory import Episode, EpisodicMemory, GridMap, ObjectState, State, Step, Trace
from bt_meta.perception.colours import scene_thresholds
from bt_meta.perception.synthetic import blank, draw_block, top_view_projection
from bt_meta.perception.topview import analyse
from bt_meta.plugins import PluginHost
from bt_meta.world.simulation.objects import LB

# -- letter A, drawn step by step ----------------------------------------------------------------------------------

ORIGIN = (0.55, 0.10)  # the letter's cell (0, 0); letter x = robot -y, letter y = robot +x
PLAN = [  # (block, x, y, shape, parent task, parent node)
    ("b0", 0, 0, "1x1", "draw_leg", "n2"),
    ("b1", 0, 1, "1x1", "draw_leg", "n2"),
    ("b2", 3, 0, "1x1", "draw_leg", "n5"),
    ("b3", 3, 1, "1x1", "draw_leg", "n5"),
    ("b5", 1.5, 1, "1x2", "draw_A_bar", "n8"),
    ("b4", 1.5, 2, "1x1", "draw_apex", "n10"),
]


def cell(x: float, y: float) -> tuple[float, float]:
    return ORIGIN[0] + y * LB, ORIGIN[1] - x * LB


def letter_view(steps: int, *, bar_shape: str = "1x2", jitter: float = 0.0, seed: int = 0):
    """The top view after the first ``steps`` placements (the bar drawn with ``bar_shape``)."""
    rng = np.random.default_rng(seed)
    projection = top_view_projection()
    image = blank(top_view_projection())
    for name, x, y, shape, _, _ in PLAN[:steps]:
        if name == "b5":
            shape = bar_shape
        bx, by = cell(x, y)
        bx, by = bx + rng.uniform(-jitter, jitter), by + rng.uniform(-jitter, jitter)
        draw_block(image, projection, bx, by, -math.pi / 2, shape, "blue")
    names = {}
    for name, x, y, *_ in PLAN[:steps]:
        names[cell(x, y)] = name

    def namer(block):
        best = min(names, key=lambda c: math.hypot(c[0] - block.centroid[0], c[1] - block.centroid[1]))
        return names[best] if math.hypot(best[0] - block.centroid[0], best[1] - block.centroid[1]) < LB / 2 else None

    return analyse(image, projection, namer=namer)


def letter_trace(seed: int) -> Trace:
    steps = []
    for i, (name, x, y, shape, parent, node) in enumerate(PLAN):
        top = letter_view(i + 1, jitter=0.002, seed=seed)
        # As the paper's instructor does: the placed block's map, centred where it was put (section 6.3).
        maps = (top.grid_map_at(cell(x, y), object_name=name, colour="blue", shape=shape),)
        steps.append(Step(i, "place", (name, str(x), str(y)), node_id=f"n{20 + i}", parent_task=parent,
                          parent_node=node, state=State(facts=(("at", name, str(x), str(y)),), grid_maps=maps)))
    episode = Episode("draw_A", "letters.yaml", "A", started=1000.0 + seed, outcome="success", finished=1001.0 + seed)
    return Trace(episode, tuple(steps))


def make_context(run: RunContext, step: int, action: str, args: tuple[str, ...]) -> StepContext:
    return StepContext(action=action, args=args, step=step, node_id=f"n{20 + step}", run=run)


@pytest.fixture(scope="module")
def letters_memory(tmp_path_factory):
    path = tmp_path_factory.mktemp("memory") / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        for seed in range(3):
            memory.write(letter_trace(seed))
    memory = EpisodicMemory.open(path, readonly=True)
    yield memory
    memory.close()


def letters_run(memory: EpisodicMemory | None) -> RunContext:
    run = RunContext(None, None, problem=SimpleNamespace(name="A", tasks=[("draw_A",)]), state=HtnState())
    if memory is not None:
        run.memory = memory  # the run's memory, as `bt-meta run --memory` will hand it over
    return run


def host_with(module, name: str) -> PluginHost:
    host = PluginHost()
    host.register(module, name, source="test")
    return host


def check(host: PluginHost, context: StepContext, observations: dict):
    result = host.call("bt_meta_expectations", context=context)
    assert not result.errors, result.errors[0].traceback if result.errors else ""
    expectations = [e for value in result.values for e in value]
    verdicts = []
    for expectation in expectations:
        verdict = host.call("bt_meta_compare", expectation=expectation, observations=observations, context=context)
        assert not verdict.errors
        verdicts.append(verdict.first)
    return expectations, verdicts


def test_gridmap_nominal_steps_match(letters_memory):
    host = host_with(gridmap_plugin, "gridmap_expectations")
    run = letters_run(letters_memory)
    for i, (name, x, y, *_) in enumerate(PLAN):
        context = make_context(run, i, "place", (name, str(x), str(y)))
        expectations, verdicts = check(host, context, {"image": letter_view(i + 1, jitter=0.002, seed=7)})
        assert len(expectations) == 1 and expectations[0].kind == "gridmap"
        assert len(expectations[0].data["traces"]) == 3
        assert verdicts[0].matched, verdicts[0].evidence


def test_gridmap_substituted_bar_is_an_unknown_entity_at_the_bar_step(letters_memory):
    host = host_with(gridmap_plugin, "gridmap_expectations")
    run = letters_run(letters_memory)
    # the legs are as remembered
    context = make_context(run, 3, "place", ("b3", "3", "1"))
    _, verdicts = check(host, context, {"image": letter_view(4, bar_shape="1x1")})
    assert verdicts[0].matched
    # the bar step: a 1x1 stands where the 1x2 should be
    context = make_context(run, 4, "place", ("b5", "1.5", "1"))
    expectations, verdicts = check(host, context, {"image": letter_view(5, bar_shape="1x1")})
    comparison = verdicts[0]
    assert not comparison.matched
    assert comparison.expectation.failure_kind.value == "unknown_entity"
    assert comparison.evidence["cells"] == 4
    assert "b5: 4 cells differ (expected blue 1x2, seen blue 1x1)" in comparison.message
    # the 3 lb window shows the bar and, as context, the legs below it
    assert comparison.evidence["maps"][0]["expected"]["grid"] == "......\n......\nbbbbbb\nbbbbbb\nb....b\nb....b"
    assert comparison.evidence["maps"][0]["observed"]["grid"] == "......\n......\nb.bb.b\nb.bb.b\nb....b\nb....b"
    # the bar is the last (only) primitive of draw_A_bar: its expectation is the task's (bubbled up)
    assert expectations[0].data["parent_task"] == "draw_A_bar" and expectations[0].data["task_end"] is True


def test_gridmap_bubbling_flags_only_the_last_primitive_of_a_task(letters_memory):
    plugin = gridmap_plugin.GridMapExpectations(letters_memory)
    run = letters_run(None)
    first = plugin.bt_meta_expectations(make_context(run, 0, "place", ("b0", "0", "0")))
    second = plugin.bt_meta_expectations(make_context(run, 1, "place", ("b1", "0", "1")))
    assert first[0].data["task_end"] is False and second[0].data["task_end"] is True
    assert second[0].data["parent_task"] == "draw_leg"


def test_gridmap_falls_back_to_action_and_arguments_when_the_plan_changed(letters_memory):
    plugin = gridmap_plugin.GridMapExpectations(letters_memory, n=2)
    run = letters_run(None)
    expectations = plugin.bt_meta_expectations(make_context(run, 9, "place", ("b5", "1.5", "1")))
    assert expectations[0].data["matched_by"] == "action" and len(expectations[0].data["traces"]) == 2
    assert plugin.bt_meta_expectations(make_context(run, 4, "place", ("b9", "7", "7"))) is None


def test_no_memory_no_expectations(tmp_path, monkeypatch):
    monkeypatch.setenv("BT_META_MEMORY", str(tmp_path / "absent.sqlite"))
    run = letters_run(None)
    context = make_context(run, 4, "place", ("b5", "1.5", "1"))
    assert gridmap_plugin.GridMapExpectations().bt_meta_expectations(context) is None
    assert keypoint_plugin.KeypointExpectations().bt_meta_expectations(context) is None


def test_unusable_memory_file_is_an_error_not_silence(tmp_path, monkeypatch):
    from bt_meta.memory import MemoryStoreError

    bad = tmp_path / "memory.sqlite"
    bad.write_text("not a database")
    monkeypatch.setenv("BT_META_MEMORY", str(bad))
    context = make_context(letters_run(None), 4, "place", ("b5", "1.5", "1"))
    with pytest.raises(MemoryStoreError, match=r"memory\.sqlite"):
        gridmap_plugin.GridMapExpectations().bt_meta_expectations(context)


def test_memory_from_environment(letters_memory, monkeypatch):
    monkeypatch.setenv("BT_META_MEMORY", str(letters_memory.path))
    plugin = gridmap_plugin.GridMapExpectations()
    expectations = plugin.bt_meta_expectations(make_context(letters_run(None), 4, "place", ("b5", "1.5", "1")))
    assert expectations and expectations[0].data["matched_by"] == "plan step"


def test_compare_needs_a_top_view_and_its_own_kind(letters_memory):
    plugin = gridmap_plugin.GridMapExpectations(letters_memory)
    expectation = plugin.bt_meta_expectations(make_context(letters_run(None), 4, "place", ("b5", "1.5", "1")))[0]
    assert gridmap_plugin.compare(expectation, {}) is None
    assert keypoint_plugin.compare(expectation, {"objects": {}}) is None
    with pytest.raises(ValueError, match="check must be one of"):
        keypoint_plugin.KeypointExpectations(check="sometimes")
    with pytest.raises(ValueError, match="n must be >= 1"):
        gridmap_plugin.GridMapExpectations(n=0)


# -- magnetic attach -----------------------------------------------------------------------------------------------

REFERENCE_AP = (0.62, -0.10, -0.16)


def attach_states(rng: np.random.Generator, *, misaligned: bool = False) -> dict[str, ObjectState]:
    """Object states after the attach motion: the active magnet on the reference's (within a few mm), or the
    active part lying on its side (its magnet facing -y, 2 cm off)."""
    noise = rng.uniform(-0.002, 0.002, 3)
    reference = ObjectState("reference_part", (0.62, -0.10, -0.18, 0, 0, 0), REFERENCE_AP, (0, 0, 1))
    if misaligned:
        active = ObjectState("active_part", (0.62, -0.08, -0.14, math.pi / 2, 0, 0),
                             tuple(np.add(REFERENCE_AP, (0.0, 0.0, 0.02)) + noise), (0, 0, -1))
    else:
        active = ObjectState("active_part", (0.62, -0.10, -0.13, 0, 0, 0),
                             tuple(np.add(REFERENCE_AP, noise)), (0, 0, -1))
    return {"active_part": active, "reference_part": reference}


ATTACH_PLAN = [("MoveTo", ("joint_above",), "AttachOnto", "n7"), ("MoveTo", ("joint",), "AttachOnto", "n7"),
               ("Grasp", (), "AttachOnto", "n7"), ("MoveTo", ("joint_above",), "AttachOnto", "n7")]


@pytest.fixture(scope="module")
def attach_memory(tmp_path_factory):
    path = tmp_path_factory.mktemp("attach") / "memory.sqlite"
    rng = np.random.default_rng(3)
    with EpisodicMemory.open(path) as memory:
        for j in range(4):
            steps = []
            for i, (action, args, parent, node) in enumerate(ATTACH_PLAN):
                objects = tuple(attach_states(rng).values())
                steps.append(Step(i, action, args, parent_task=parent, parent_node=node,
                                  state=State(objects=objects)))
            memory.write(Trace(Episode("MagneticAttach", "magnetic_attach.yaml", "attach_only",
                                       started=time.time() + j, outcome="success"), tuple(steps)))
    memory = EpisodicMemory.open(path, readonly=True)
    yield memory
    memory.close()


def attach_run(memory: EpisodicMemory) -> RunContext:
    problem = SimpleNamespace(name="attach_only", tasks=[("MagneticAttach", "active_part", "reference_part")])
    run = RunContext(None, None, problem=problem, state=HtnState())
    run.memory = memory
    return run


def observed(states: dict[str, ObjectState]) -> dict[str, dict]:
    """As ground-truth perception gives them: dicts with the normal in the base frame."""
    return {name: {"name": name, "pose": list(s.pose), "ap": list(s.ap), "an": list(s.an_base)}
            for name, s in states.items()}


def test_keypoint_nominal_attach_matches_and_misaligned_attach_does_not(attach_memory):
    host = host_with(keypoint_plugin, "keypoint_expectations")
    run = attach_run(attach_memory)
    rng = np.random.default_rng(11)
    context = make_context(run, 3, "MoveTo", ("joint_above",))
    expectations, verdicts = check(host, context, {"objects": observed(attach_states(rng))})
    assert [e.kind for e in expectations] == ["keypoint"]
    data = expectations[0].data
    assert {data["active"], data["reference"]} == {"active_part", "reference_part"}
    assert data["expected"]["n"] == 4 and data["expected"]["r_n"] == pytest.approx(math.pi)
    assert data["task_end"] is True and data["parent_task"] == "AttachOnto"
    assert verdicts[0].matched
    _, verdicts = check(host, context, {"objects": observed(attach_states(rng, misaligned=True))})
    comparison = verdicts[0]
    assert not comparison.matched
    assert comparison.evidence["failed"] == ["r_p", "r_n"]
    assert "R_n 90.0 deg, expected 180.0 deg" in comparison.message


def test_keypoint_thresholds_and_check_setting(attach_memory):
    run = attach_run(attach_memory)
    rng = np.random.default_rng(5)
    misaligned = observed(attach_states(rng, misaligned=True))
    # R_n only, with a tolerance wider than the misalignment: no mismatch
    loose = keypoint_plugin.KeypointExpectations(position_tolerance=None, angle_tolerance=math.radians(100))
    expectation = loose.bt_meta_expectations(make_context(run, 3, "MoveTo", ("joint_above",)))[0]
    assert keypoint_plugin.compare(expectation, {"objects": misaligned}).matched
    # check="task_end": only the last primitive of AttachOnto carries an expectation
    at_end = keypoint_plugin.KeypointExpectations(check="task_end")
    assert at_end.bt_meta_expectations(make_context(run, 1, "MoveTo", ("joint",))) is None
    assert at_end.bt_meta_expectations(make_context(run, 3, "MoveTo", ("joint_above",)))
    # explicit pairs naming an object nobody observes: a mismatch that says so
    named = keypoint_plugin.KeypointExpectations(pairs=[("active_part", "reference_part")])
    expectation = named.bt_meta_expectations(make_context(run, 3, "MoveTo", ("joint_above",)))[0]
    missing = keypoint_plugin.compare(expectation, {"objects": {"reference_part": misaligned["reference_part"]}})
    assert not missing.matched and "active_part not observed" in missing.message


PICK_PLAN = [("MoveTo", ("active_above",), "PickPart", "n3"), ("MoveTo", ("active_grasp",), "PickPart", "n3"),
             ("Grasp", (), "PickPart", "n3"), ("MoveTo", ("active_above",), "PickPart", "n3")]


def picked_states(shift: tuple[float, float, float] = (0.0, 0.0, 0.0), roll: float = 0.0
                  ) -> dict[str, ObjectState]:
    """After PickPart: the active part held 10 cm up above where it lay, 30 cm from the reference; ``shift`` moves
    where it lay (a nominal-equivalent scene), ``roll`` lays it on its side (magnet facing -y)."""
    reference = ObjectState("reference_part", (0.62, -0.10, -0.18, 0, 0, 0), REFERENCE_AP, (0, 0, 1))
    x, y, z = np.add((0.58, -0.40, -0.07), shift)
    normal = (0, math.sin(roll), -math.cos(roll))
    active = ObjectState("active_part", (x, y, z, roll, 0, 0), (x, y, z - 0.03), normal)
    return {"active_part": active, "reference_part": reference}


@pytest.fixture(scope="module")
def pick_memory(tmp_path_factory):
    path = tmp_path_factory.mktemp("pick") / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        for j in range(3):
            steps = [Step(i, action, args, parent_task=parent, parent_node=node,
                          state=State(objects=tuple(picked_states().values())))
                     for i, (action, args, parent, node) in enumerate(PICK_PLAN)]
            memory.write(Trace(Episode("MagneticAttach", "magnetic_attach.yaml", "attach_only",
                                       started=time.time() + j, outcome="success"), tuple(steps)))
    memory = EpisodicMemory.open(path, readonly=True)
    yield memory
    memory.close()


@pytest.mark.parametrize("shift", [(0.04, 0.0, 0.0), (0.0, -0.03, 0.0), (0.03, 0.03, 0.0)])
def test_a_part_shifted_a_few_cm_raises_no_keypoint_mismatch_before_the_parts_meet(pick_memory, shift):
    """Before the attach, R_p is where the parts lie on the table (30 cm apart): not informative, not checked. R_n
    is, and a part on its side is still caught."""
    host = host_with(keypoint_plugin, "keypoint_expectations")
    context = make_context(attach_run(pick_memory), 3, "MoveTo", ("active_above",))
    expectations, verdicts = check(host, context, {"objects": observed(picked_states(shift))})
    assert expectations[0].data["checked"] == ["r_n"] and expectations[0].data["position_tolerance"] is None
    assert verdicts[0].matched, verdicts[0].message
    _, verdicts = check(host, context, {"objects": observed(picked_states(shift, roll=math.pi / 2))})
    assert not verdicts[0].matched and verdicts[0].evidence["failed"] == ["r_n"]


def test_r_p_is_checked_where_the_parts_meet_and_everywhere_without_a_contact_distance(attach_memory, pick_memory):
    plugin = keypoint_plugin.KeypointExpectations()
    at_attach = plugin.bt_meta_expectations(make_context(attach_run(attach_memory), 3, "MoveTo", ("joint_above",)))
    assert at_attach[0].data["checked"] == ["r_p", "r_n"]
    everywhere = keypoint_plugin.KeypointExpectations(contact_distance=None)
    expectation = everywhere.bt_meta_expectations(make_context(attach_run(pick_memory), 3, "MoveTo",
                                                               ("active_above",)))[0]
    assert not keypoint_plugin.compare(expectation, {"objects": observed(picked_states((0, 0.04, 0)))}).matched
    with pytest.raises(ValueError, match="contact_distance must be >= 0 or None, got -1"):
        keypoint_plugin.KeypointExpectations(contact_distance=-1)


def test_configure_replaces_the_module_plugin(attach_memory):
    try:
        keypoint_plugin.configure(memory=attach_memory, angle_tolerance=None, position_tolerance=0.5)
        context = make_context(attach_run(attach_memory), 3, "MoveTo", ("joint_above",))
        expectation = keypoint_plugin.bt_meta_expectations(context)[0]
        assert expectation.data["position_tolerance"] == 0.5 and expectation.data["angle_tolerance"] is None
    finally:
        keypoint_plugin.configure()


# -- end to end in the simulator: record nominal A, then run with the bar substituted --------------------------------


def _tick(harness, limit: int = 4000):
    from py_trees.common import Status

    status, ticks = Status.RUNNING, 0
    while status is Status.RUNNING and ticks < limit:
        status = harness.run.tick(harness.root)
        ticks += 1
    return status


def _record_nominal(path, problem: str, observe_state) -> tuple[Step, ...]:
    """Run ``problem`` in the simulator (seed 0) to SUCCESS with a plugin recording ``observe_state(world, context)``
    (a :class:`State`) after each step; the steps of the trace a nominal run leaves in memory."""
    from bt_meta.plugins import create_plugin_host, hookimpl
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    recorded: dict[int, tuple[StepContext, State]] = {}

    class Recorder:
        @hookimpl
        def bt_meta_observe(self, world, context):
            recorded[context.step] = (context, observe_state(world, context))

    with quiet_stdout():
        world = SimWorld.from_task_file(path, problem, seed=0)
    try:
        harness = TreeHarness.from_file(path, problem, world=world, plugins=create_plugin_host(
            entry_points=False, plugins=[("recorder", Recorder())]))
        assert _tick(harness).value == "SUCCESS"
        tree = harness.compiled.plan_result.tree
    finally:
        world.close()
    steps = []
    for i in sorted(recorded):
        context, state = recorded[i]
        parent = tree.nodes[tree.nodes[context.node_id].parent]
        steps.append(Step(i, context.action, context.args, node_id=context.node_id, parent_task=parent.task[0],
                          parent_node=parent.id, state=state))
    return tuple(steps)


@pytest.mark.slow
def test_recorded_nominal_a_then_substituted_bar_raises_gridmap_mismatch_at_the_bar_step(tmp_path, monkeypatch):
    import bt_meta_plugins.camera_perception as camera_plugin

    from bt_meta.plugins import create_plugin_host
    from bt_meta.resources import trees_dir
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    path = trees_dir() / "letters.yaml"
    camera = camera_plugin.CameraPerception()

    def placed_block_grid_map(world, context) -> State:
        """After each place, the placed block's grid-map at its true position (the instructor's key)."""
        maps = camera.object_grid_maps(world, camera.look(world))
        return State(grid_maps=(maps[world.object_name(context.args[0])],))

    steps = _record_nominal(path, "A", placed_block_grid_map)
    memory_path = tmp_path / "memory.sqlite"
    with EpisodicMemory.open(memory_path) as memory:
        memory.write(Trace(Episode("draw_A", str(path), "A", started=time.time(), outcome="success"), steps))
    monkeypatch.setenv("BT_META_MEMORY", str(memory_path))

    def run_variant(variant: str):
        plugins = create_plugin_host(entry_points=False, plugins=[
            ("camera_perception", camera_plugin), ("gridmap_expectations", gridmap_plugin)])
        with quiet_stdout():
            world = SimWorld.from_task_file(path, "A", variant=variant, seed=0)
        try:
            harness = TreeHarness.from_file(path, "A", world=world, plugins=plugins)
            return _tick(harness).value, harness.run.failures
        finally:
            world.close()

    status, failures = run_variant("A_two_1x1_same_colour")
    assert status == "FAILURE"
    assert len(failures) == 1
    failure = failures[0]
    assert (failure.step, failure.action, tuple(failure.args)) == (4, "place", ("b5", "1.5", "1"))
    assert failure.kind.value == "unknown_entity"
    assert "expected blue 1x2, seen red 1x1" in failure.message
    status, failures = run_variant("nominal")
    assert status == "SUCCESS" and failures == []


@pytest.mark.slow
@pytest.mark.parametrize(("check_at", "step"), [("all", 0), ("task_end", 3)])
def test_recorded_nominal_attach_then_part_on_its_side_raises_keypoint_mismatch(tmp_path, check_at, step):
    import bt_meta_plugins.ground_truth_perception as truth_plugin

    from bt_meta.plugins import create_plugin_host
    from bt_meta.resources import trees_dir
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    path = trees_dir() / "magnetic_attach.yaml"

    def object_states(world, context) -> State:
        return State(objects=tuple(
            ObjectState(s.name, s.pose, s.ap, s.an_object) for s in world.sim.object_states().values()))

    steps = _record_nominal(path, "attach_only", object_states)
    memory = EpisodicMemory.open(tmp_path / "memory.sqlite")
    memory.write(Trace(Episode("MagneticAttach", str(path), "attach_only", started=time.time(), outcome="success"),
                       steps))

    def run_variant(variant: str):
        plugin = keypoint_plugin.KeypointExpectations(memory, check=check_at)
        plugins = create_plugin_host(entry_points=False, plugins=[
            ("ground_truth_perception", truth_plugin), ("keypoint_expectations", plugin)])
        with quiet_stdout():
            world = SimWorld.from_task_file(path, "attach_only", variant=variant, seed=0)
        try:
            harness = TreeHarness.from_file(path, "attach_only", world=world, plugins=plugins)
            return _tick(harness).value, harness.run.failures
        finally:
            world.close()

    try:
        status, failures = run_variant("active_on_side")
        assert status == "FAILURE" and len(failures) == 1
        failure = failures[0]
        assert failure.step == step and failure.kind.value == "unexpected_configuration"
        assert "R_n 90.0 deg, expected 180.0 deg" in failure.message
        status, failures = run_variant("nominal")
        assert status == "SUCCESS" and failures == []
    finally:
        memory.close()


def test_gridmap_colour_is_ignored_unless_asked(letters_memory):
    """A red 1x2 instead of the blue one (section 6.4, first variant) has the same form: only compare_colour sees it."""
    projection = top_view_projection()
    image = blank(projection)
    for name, x, y, shape, *_ in PLAN[:5]:
        draw_block(image, projection, *cell(x, y), -math.pi / 2, shape, "red" if name == "b5" else "blue")
    observations = {"image": analyse(image, projection)}
    context = make_context(letters_run(None), 4, "place", ("b5", "1.5", "1"))
    plain = gridmap_plugin.GridMapExpectations(letters_memory).bt_meta_expectations(context)[0]
    assert gridmap_plugin.compare(plain, observations).matched
    strict = gridmap_plugin.GridMapExpectations(letters_memory, compare_colour=True).bt_meta_expectations(context)[0]
    verdict = gridmap_plugin.compare(strict, observations)
    assert not verdict.matched and verdict.evidence["cells"] == 8


def _bar_observations(bar_colour: str) -> dict:
    projection = top_view_projection()
    image = blank(projection)
    for name, x, y, shape, *_ in PLAN[:5]:
        draw_block(image, projection, *cell(x, y), -math.pi / 2, shape, bar_colour if name == "b5" else "blue")
    return {"image": analyse(image, projection, thresholds=scene_thresholds(TABLE_COLOUR))}


@pytest.mark.parametrize(("seen", "symbol", "matched"), [
    ("green", "blue", False),   # the symbols say blue: a green bar is the wrong entity
    ("yellow", "blue", False),
    ("blue", "blue", True),
    ("green", "green", True),   # the symbols say green: as seen
    ("green", None, True),      # no colour symbol: occupancy only, as the paper's
])
def test_gridmap_colour_matters_where_the_task_symbols_name_it(letters_memory, seen, symbol, matched):
    state = HtnState([("shape", "b5", "1x2")] + ([("colour", "b5", symbol)] if symbol else []))
    context = StepContext(action="place", args=("b5", "1.5", "1"), step=4, node_id="n24",
                          run=letters_run(None), state_before=state)
    plugin = gridmap_plugin.GridMapExpectations(letters_memory, symbol_colours=True)
    expectation = plugin.bt_meta_expectations(context)[0]
    assert expectation.data["colours"] == ({"b5": symbol} if symbol else {})
    verdict = gridmap_plugin.compare(expectation, _bar_observations(seen))
    assert verdict.matched is matched, verdict.evidence
    if not matched:
        assert verdict.expectation.failure_kind.value == "unknown_entity"
        assert verdict.evidence["maps"][0]["off_colour"] == 8
        assert f"b5: 8 cells differ (expected blue 1x2, seen {seen} 1x2; 8 of another colour" in verdict.message
    # the other blocks' colour does not matter: only the step's arguments are looked at
    leg = StepContext(action="place", args=("b3", "3", "1"), step=3, node_id="n23", run=letters_run(None),
                      state_before=state)
    assert plugin.bt_meta_expectations(leg)[0].data["colours"] == {}
    # by default (the paper's occupancy, as the demo's red bar needs) no colour is compared
    assert gridmap_plugin.GridMapExpectations(letters_memory).bt_meta_expectations(context)[0].data["colours"] == {}


def test_gridmap_symbol_colours_from_the_environment(monkeypatch):
    from bt_meta.errors import ConfigError

    monkeypatch.setenv(gridmap_plugin.ENV_COLOURS, "symbols")
    assert gridmap_plugin.GridMapExpectations().symbol_colours is True
    monkeypatch.setenv(gridmap_plugin.ENV_COLOURS, "occupancy")
    assert gridmap_plugin.GridMapExpectations().symbol_colours is False
    monkeypatch.setenv(gridmap_plugin.ENV_COLOURS, "maybe")
    with pytest.raises(ConfigError, match="BT_META_GRIDMAP_COLOURS must be 'symbols' or 'occupancy', got 'maybe'"):
        gridmap_plugin.GridMapExpectations()


def test_camera_perception_needs_a_camera():
    import bt_meta_plugins.camera_perception as camera_plugin

    assert camera_plugin.bt_meta_observe(world=SimpleNamespace(), context=None, request=None) is None
    assert camera_plugin.CameraPerception().camera_for(None) is None
    from bt_meta.perception.hsv import PerceptionConfigError

    with pytest.raises(PerceptionConfigError, match="expected a mapping with a 'colours' key"):
        camera_plugin.CameraPerception(thresholds={"colour": {}})


@pytest.mark.slow
@pytest.mark.parametrize(("family", "task_file", "variant"), [
    ("magnetic", "magnetic_attach.yaml", "active_shifted"), ("housing", "housing_insertion.yaml", "parts_shifted")])
def test_a_shifted_nominal_equivalent_scene_raises_nothing_with_keypoint_monitors(tmp_path, family, task_file,
                                                                                  variant):
    """Recorded nominal, then the parts (and board) moved a few cm: monitors at every task end, no mismatch."""
    from bt_meta.demo.runner import memory_environment, record_demonstration, run_variant
    from bt_meta.demo.scenario import Demonstration, VariantRun
    from bt_meta.meta import RefinementStore
    from bt_meta.runs.capture import Progress

    path = tmp_path / "memory.sqlite"
    progress = Progress(quiet=True)
    with memory_environment(path):
        memory = EpisodicMemory.open(path)
        try:
            assert record_demonstration(Demonstration(family, task_file, "nominal", 0), memory,
                                        progress).status == "recorded"
            with RefinementStore.open(path) as refinements:
                outcome = run_variant(VariantRun(family, task_file, "nominal", variant, 0), memory, refinements,
                                      progress, configuration="dual_kp_monitor", pictures=False)
        finally:
            memory.close()
    assert outcome.report["status"] == "success", outcome.report["stop_reason"]
    assert outcome.report["failures"] == [] and outcome.report["attempts"] == []


class WindowView:
    """A top view that shows one fixed window (no single block found near the centroid: blobs merged). Letters
    are colour codes: ``b`` and ``#`` the block's colour, ``g`` another one."""

    CODES = {".": 0, "b": 1, "#": 1, "g": 2}

    def __init__(self, occupancy: list[str]) -> None:
        self.occupancy = np.array([[self.CODES[c] for c in row] for row in occupancy], dtype=np.uint8)

    def block_near(self, centroid: Any, radius: float) -> None:
        return None

    def grid_map_at(self, centroid: Any, **kwargs: Any) -> GridMap:
        return GridMap(self.occupancy, centroid=tuple(centroid))


EXPECTED_LEG = ["......", "......", "..bb..", "..bb..", "..bb..", "..bb.."]  # the placed block on its leg


@pytest.mark.parametrize(("observed", "matched"), [
    (["....##", ".....#", "..bb..", "..bb..", "..bb..", "..bb.."], True),   # a distractor in the window's corner
    (["...###", "...###", "..bb..", "..bb..", "..bb..", "..bb.."], False),  # one of its colour touching it
    (["...ggg", "...ggg", "..bb..", "..bb..", "..bb..", "..bb.."], True),   # one of another colour touching it
    (["......", "gggg..", "gggg..", "..bb..", "..bb..", "..bb.."], False),  # one of another colour on its cells
    (["bb....", "bb....", "......", "......", "..bb..", "..bb.."], False),  # the block landed a cell away
    (["......", "......", "......", "......", "..bb..", "..bb.."], False),  # the block is not there
    # a distractor against the leg below (over one of its cells) and out into the window's corner: not the step's
    (["......", "......", "..bb..", "..bb..", "..bggg", "..bggg"], True),
    (["......", "......", "..bb..", "..bb..", "..bbgg", "..bggg"], True),
    # ... but the leg below knocked away, or the step's block one cell off, is still seen
    (["......", "......", "..bb..", "..bb..", "....gg", "....gg"], False),
    (["......", "......", "...bb.", "...bb.", "..bb..", "..bb.."], False),  # one cell to the side
    (["......", "..bb..", "..bb..", "......", "..bb..", "..bb.."], False),  # one cell towards the far edge
    (["......", "......", "...bbg", "...bbg", "..bbgg", "..bggg"], False),  # one cell off, a distractor by it
    # the leg below is a 1x2 a repair laid across the leg and the bar (letters_H 0047): merged with the block into
    # one blob, it reaches out beyond the leg's remembered cells -- not the step's doing
    (["......", "......", "..bb..", "..bb..", "bbbb..", "bbbb.."], True),
    (["......", "......", "...bb.", "...bb.", "bbbb..", "bbbb.."], False),  # ... with the block one cell off
    (["......", "......", "..bbbb", "..bbbb", "..bb..", "..bb.."], False),  # a 1x2 where the 1x1 goes
])
def test_gridmap_counts_only_blobs_that_meet_what_memory_expected(observed, matched):
    expected = GridMap(WindowView(EXPECTED_LEG).occupancy, object_name="b5", colour="blue", shape="1x1",
                       centroid=(0.672, -0.083))
    expectation = Expectation(kind=gridmap_plugin.KIND, description="grid-maps after place(b5, 3, 2)", data={
        "traces": [{"episode": 1, "maps": [expected]}], "max_cells": 2, "compare_colour": False,
        "rotations": False, "recentre_radius": 0.25 * LB, "parent_task": "draw_tall_leg", "task_end": True})
    comparison = gridmap_plugin.compare(expectation, {"image": WindowView(observed)})
    assert comparison.matched is matched, comparison.evidence


EXPECTED_BAR = ["......", "......", ".bbbb.", ".bbbb.", "g....g", "g....g"]  # a 1x2 bar over legs of another colour


@pytest.mark.parametrize(("observed", "matched"), [
    (EXPECTED_BAR, True),
    (["......", "......", ".bbbb.", ".bbbb.", "g..ggg", "g..ggg"], True),  # a distractor against a leg, into the corner
    (["......", "......", "..bbbb", "..bbbb", "g....g", "g....g"], False),  # the bar one cell off
    (["......", ".bbbb.", ".bbbb.", "......", "g....g", "g....g"], False),  # the bar one cell towards the far edge
    (["......", "......", ".bbbb.", ".bbbb.", "......", "......"], False),  # the legs knocked away
])
def test_gridmap_compares_the_cells_the_steps_block_can_cover(observed, matched):
    """A blob that meets only a neighbour's remembered cells (not the cells the step's 1x2 can cover) counts there
    only; the bar itself off by a cell still differs."""
    expected = GridMap(WindowView(EXPECTED_BAR).occupancy, object_name="b5", colour="blue", shape="1x2",
                       centroid=(0.611, -0.008))
    expectation = Expectation(kind=gridmap_plugin.KIND, description="grid-maps after place(b5, 1.5, 1)", data={
        "traces": [{"episode": 1, "maps": [expected]}], "max_cells": 2, "compare_colour": False,
        "rotations": False, "recentre_radius": 0.25 * LB, "parent_task": "draw_A_bar", "task_end": True})
    comparison = gridmap_plugin.compare(expectation, {"image": WindowView(observed)})
    assert comparison.matched is matched, comparison.evidence


def test_gridmap_tells_what_was_there_before_the_run_s_first_step(letters_memory):
    """The first step of a run has no top view of an earlier step: one of the block's colour touching it is a
    mismatch -- unless the view the run started with (``RunContext.start_observations``) already showed it there
    (generated letters_A s2 0124: a yellow 1x2 beside the cell of b0, recoloured yellow)."""
    expected = GridMap(WindowView(EXPECTED_LEG).occupancy, object_name="b5", colour="blue", shape="1x1",
                       centroid=(0.672, -0.083))
    expectation = Expectation(kind=gridmap_plugin.KIND, description="grid-maps after place(b5, 3, 2)", data={
        "traces": [{"episode": 1, "maps": [expected]}], "max_cells": 2, "compare_colour": False,
        "rotations": False, "recentre_radius": 0.25 * LB, "parent_task": "draw_tall_leg", "task_end": True})
    after = {"image": WindowView(["...###", "...###", "..bb..", "..bb..", "..bb..", "..bb.."])}
    started = {"image": WindowView(["...###", "...###", "......", "......", "..bb..", "..bb.."])}
    for start, matched in ((None, False), (started, True)):
        run = letters_run(None)
        run.start_observations = start
        plugin = gridmap_plugin.GridMapExpectations()
        verdict = plugin.bt_meta_compare(expectation, after, make_context(run, 0, "place", ("b5", "3", "2")))
        assert verdict.matched is matched, verdict.evidence

