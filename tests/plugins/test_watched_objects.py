"""Everything the plan moves is watched (issue 31): the recorder keeps a grid-map of every object a step names or
moves, whatever its type; the grid-map plugin checks an object where a step put it by numbers of a frame, and any
other one as it looks where it is; the keypoint plugin checks the orientation of every object a remembered step
moved -- as that step left it, or changed as it changed it -- so a part lifted where it lay turned 45 degrees raises
nothing while a part twisted in the fingers, landed on another face or gone does."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import bt_meta_plugins.gridmap_expectations as gridmap_plugin
import bt_meta_plugins.keypoint_expectations as keypoint_plugin
import pytest

from bt_meta.bt.context import RunContext
from bt_meta.bt.expectations import StepContext
from bt_meta.htn import State as HtnState
from bt_meta.memory import Episode, EpisodicMemory, ObjectState, State, Step, Trace
from bt_meta.memory.recorder import TraceRecorder, moved_objects

UP = (0.0, 0.0, 1.0)


def _state(pose: tuple[float, ...], name: str = "part") -> ObjectState:
    return ObjectState(name, pose, pose[:3], UP)


def test_moved_objects_are_those_shifted_or_turned_by_the_step():
    before = [_state((0.5, 0.0, 0.0, 0.0, 0.0, 0.0), "a"), _state((0.6, 0.0, 0.0, 0.0, 0.0, 0.0), "b"),
              _state((0.7, 0.0, 0.0, 0.0, 0.0, 0.0), "c"), _state((0.8, 0.0, 0.0, 0.0, 0.0, 0.0), "d")]
    after = [_state((0.5, 0.0, 0.1, 0.0, 0.0, 0.0), "a"),  # lifted
             _state((0.603, 0.0, 0.0, 0.0, 0.0, 0.0), "b"),  # nudged 3 mm: not the step's doing
             _state((0.7, 0.0, 0.0, 0.0, 0.0, math.radians(30.0)), "c"),  # turned on the spot
             _state((0.8, 0.0, 0.0, math.radians(90.0), 0.0, 0.0), "d")]  # tipped over
    assert moved_objects(before, after) == ["a", "c", "d"]


# -- a two-step demonstration: the part lifted where it lies, then carried to an absolute pose turned 90 degrees --

LIFTED = 0.10
CARRIED = (0.62, -0.10, 0.05, 0.0, 0.0, math.radians(90.0))


def _trace(seed: int) -> Trace:
    start = (0.58, -0.40, 0.0, 0.0, 0.0, 0.0)
    lifted = (0.58, -0.40, LIFTED, 0.0, 0.0, 0.0)
    states = [start, lifted, CARRIED]
    steps = tuple(Step(i, "MoveTo", (pose,), node_id=f"n{i}", parent_task="carry", parent_node="n9",
                       state=State(objects=(_state(states[i + 1]), _state((0.7, 0.2, 0.0, 0, 0, 0), "other"))))
                  for i, pose in enumerate(("lift", "joint")))
    episode = Episode("carry", "carry.yaml", "nominal", started=100.0 + seed, outcome="success", finished=101.0 + seed)
    return Trace(episode, steps, initial=State(objects=(_state(start), _state((0.7, 0.2, 0.0, 0, 0, 0), "other"))))


@pytest.fixture(scope="module")
def carry_memory(tmp_path_factory):
    path = tmp_path_factory.mktemp("memory") / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        for seed in range(2):
            memory.write(_trace(seed))
    memory = EpisodicMemory.open(path, readonly=True)
    yield memory
    memory.close()


def _check(memory: EpisodicMemory, step: int, action_arg: str, started: tuple[float, ...] | None,
           seen: tuple[float, ...] | None):
    world = SimpleNamespace(step_start_poses={} if started is None else {"part": list(started)})
    run = RunContext(world, None, problem=SimpleNamespace(name="nominal", tasks=[("carry",)]), state=HtnState())
    run.memory = memory
    context = StepContext(action="MoveTo", args=(action_arg,), step=step, node_id=f"n{step}", run=run)
    plugin = keypoint_plugin.KeypointExpectations(memory)
    expectations = [e for e in plugin.bt_meta_expectations(context) or () if e.data.get("check") == "orientation"]
    assert [e.data["object"] for e in expectations] == ["part"]  # "other" never moved: not watched
    objects = {} if seen is None else {"part": {"pose": list(seen)}}
    return keypoint_plugin.compare(expectations[0], {"objects": objects})


def test_a_part_lifted_where_it_lay_turned_keeps_its_own_heading(carry_memory):
    turned = math.radians(45.0)
    assert _check(carry_memory, 0, "lift", (0.60, -0.38, 0.0, 0.0, 0.0, turned),
                  (0.60, -0.38, LIFTED, 0.0, 0.0, turned)).matched  # as the step changed it (not at all)
    assert _check(carry_memory, 1, "joint", (0.60, -0.38, LIFTED, 0.0, 0.0, turned), CARRIED).matched  # as left


def test_a_part_twisted_in_the_fingers_or_on_another_face_is_a_mismatch(carry_memory):
    twisted = (*CARRIED[:5], CARRIED[5] + math.radians(40.0))
    result = _check(carry_memory, 1, "joint", (0.58, -0.40, LIFTED, 0.0, 0.0, 0.0), twisted)
    assert not result.matched
    assert "heading is 40 degrees off" in result.message
    tipped = (0.58, -0.40, LIFTED, math.radians(90.0), 0.0, 0.0)
    result = _check(carry_memory, 0, "lift", (0.58, -0.40, 0.0, 0.0, 0.0, 0.0), tipped)
    assert not result.matched and "base faces 90 degrees off" in result.message
    assert not _check(carry_memory, 0, "lift", (0.58, -0.40, 0.0, 0.0, 0.0, 0.0), None).matched  # gone


def test_without_where_the_step_started_only_where_it_left_the_part_counts(carry_memory):
    turned = math.radians(45.0)
    assert not _check(carry_memory, 0, "lift", None, (0.60, -0.38, LIFTED, 0.0, 0.0, turned)).matched
    assert _check(carry_memory, 0, "lift", None, (0.60, -0.38, LIFTED, 0.0, 0.0, 0.0)).matched


def _named(args: tuple[str, ...], objects: set[str]):
    def object_name(symbol: str) -> str:
        if symbol not in objects:
            raise KeyError(symbol)
        return symbol

    world = SimpleNamespace(object_name=object_name)
    run = RunContext(world, None, problem=None, state=HtnState())
    return gridmap_plugin._named(StepContext(action="x", args=args, run=run))


def test_the_grid_map_checks_where_only_what_a_step_put_at_numbers_of_a_frame():
    assert _named(("b5", "1.5", "1"), {"b5"}) == ({"b5"}, True)  # place(b5, 1.5, 1): there
    assert _named(("housing",), {"housing"}) == ({"housing"}, False)  # CloseGripper(housing): as it looks
    assert _named(("housing", "housing_hole"), {"housing"}) == ({"housing"}, False)  # into another part
    assert _named(("active_above",), {"active"}) == (set(), False)  # a pose symbol: what it moved, as it looks


@pytest.mark.slow
def test_the_recorder_keeps_a_grid_map_of_a_catalogue_cylinder_a_step_names(tmp_path: Path):
    """The pin (a catalogue cylinder) used to get no grid-map at record time: only blocks did."""
    from bt_meta.resources import trees_dir
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    (tmp_path / "pins.yaml").write_text(
        "types:\n  pin:\n    description: A pin\n    shape: cylinder\n    radius: 0.012\n    length: 0.07\n"
        "    mass: 0.03\n    colour: red\n    features:\n"
        "      bottom: {point: [0.0, 0.0, -0.035], normal: [0.0, 0.0, -1.0]}\n"
        "    grasp_frames:\n      top: [0.0, 0.0, 0.039, 180, 0, 180]\n")
    scene = (trees_dir() / "scenes" / "letters_A.yaml").read_text(encoding="utf-8")
    scene = scene.replace("scene: letters_A", "scene: pins\ncatalogue: [pins.yaml]")
    scene = scene.replace("{name: b0, type: megablok_1x1, colour: blue,", "{name: b0, type: pin,")
    (tmp_path / "scene.yaml").write_text(scene)
    with quiet_stdout():
        world = SimWorld.from_task_file(trees_dir() / "letters.yaml", "A", scene=tmp_path / "scene.yaml")
    try:
        recorder = TraceRecorder()
        before = world.sim.object_states()
        maps = recorder._grid_maps(world, ("b0", "0", "0"), {})
        assert [m.object_name for m in maps] == ["b0"]
        assert maps[0].shape is None and maps[0].colour == "red"
        assert int(maps[0].occupancy.astype(bool).sum()) >= 1  # the pin is seen in its window
        assert before["b0"].shape is None
        moved = recorder._grid_maps(world, ("lift",), {}, moved=["b0", "b1"])
        assert [m.object_name for m in moved] == ["b0", "b1"]  # what a step moved, named or not
    finally:
        world.close()


def test_what_the_robot_carries_is_left_to_its_orientation():
    """A part held, and what is joined to it, is not judged from above (a lifted subassembly hides its parts)."""
    sim = SimpleNamespace(robot=SimpleNamespace(arms={"right": None, "left": None}),
                          held=lambda arm: "active" if arm == "right" else None,
                          attachments=lambda: [("active", "reference"), ("reference", "base_plate"), ("x", "y")])
    context = SimpleNamespace(world=SimpleNamespace(sim=sim))
    assert gridmap_plugin._carried(context) == {"active", "reference", "base_plate"}
    assert gridmap_plugin._carried(SimpleNamespace(world=None)) == set()
