"""The perceived state: sensing confirms what holds and drops what it contradicts (real simulator and camera)."""

from __future__ import annotations

import math

import pytest

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def world():
    from bt_meta.campaign.episode import variant_world
    from bt_meta.campaign.families import family
    from bt_meta.world.simulation.scenes import load_scene

    _, _, world = variant_world(family("letters_A").task_path(), "A", load_scene("letters_A").path, None, 0)
    yield world
    world.close()


@pytest.mark.parametrize("noisy", [False, True])
def test_a_block_at_its_cell_is_seen_and_a_moved_one_is_not(world, noisy):
    from bt_meta.sensing.noise import SensingNoise
    from bt_meta.sensing.perceived import PerceivedState

    sim = world.sim
    x, y, yaw = world.ground_cell("letter", "0", "0")
    sim.move_object("b0", (x, y, sim.object_pose("b0")[2], 0.0, 0.0, yaw))
    sim.settle(60)
    placed = ("at", "b0", "0", "0")
    world.apply_symbolic([placed], [("available", "b0")])
    plugin = PerceivedState(seed=1, noise=SensingNoise() if noisy else SensingNoise.perfect())
    observed = plugin.bt_meta_observe(world, None)
    assert placed in observed["symbolic_state"]
    assert observed["perceived"]["contradicted"] == []
    sim.move_object("b0", (0.72, -0.55, sim.object_pose("b0")[2], 0.0, 0.0, 0.0))  # knocked away
    sim.settle(60)
    observed = plugin.bt_meta_observe(world, None)
    assert placed not in observed["symbolic_state"]
    assert observed["perceived"]["contradicted"] == [list(placed)]
    assert placed in world.symbolic_state()  # the bookkept state still believes it
    world.apply_symbolic([], [placed])


@pytest.mark.parametrize("colour", ["green", "yellow", "orange", "red", "grey"])
def test_a_block_of_any_declared_colour_at_its_cell_is_seen_under_changing_light(world, colour):
    """The perceived world's thresholds are those of every declared colour, its frames balanced against the table:
    a green b0 at its cell is where the symbols say, in every frame (each with its own lighting gain)."""
    import pybullet

    from bt_meta.sensing.noise import SensingNoise
    from bt_meta.sensing.perceived import PerceivedState
    from bt_meta.world.simulation.objects import COLOURS

    sim = world.sim
    body = sim.body_id("b0")
    x, y, yaw = world.ground_cell("letter", "0", "0")
    sim.move_object("b0", (x, y, sim.object_pose("b0")[2], 0.0, 0.0, yaw))
    sim.settle(60)
    placed = ("at", "b0", "0", "0")
    world.apply_symbolic([placed], [("available", "b0")])
    try:
        for link in range(-1, pybullet.getNumJoints(body, physicsClientId=sim.client)):
            pybullet.changeVisualShape(body, link, rgbaColor=COLOURS[colour], physicsClientId=sim.client)
        for seed in range(3):
            plugin = PerceivedState(seed=seed, noise=SensingNoise())
            for _ in range(2):
                observed = plugin.bt_meta_observe(world, None)
                assert observed["perceived"]["contradicted"] == [], (seed, observed["perceived"])
                assert any(b["colour"] == colour and math.hypot(b["centroid"][0] - x, b["centroid"][1] - y) < 0.02
                           for b in observed["perceived"]["blocks"]), (seed, observed["perceived"]["blocks"])
    finally:
        for link in range(-1, pybullet.getNumJoints(body, physicsClientId=sim.client)):
            pybullet.changeVisualShape(body, link, rgbaColor=COLOURS["blue"], physicsClientId=sim.client)
        world.apply_symbolic([("available", "b0")], [placed])


def test_a_1x1_where_a_1x2_belongs_contradicts_the_bar(world):
    from bt_meta.sensing.noise import SensingNoise
    from bt_meta.sensing.perceived import PerceivedState

    sim = world.sim
    x, y, yaw = world.ground_cell("letter", "1", "1")  # the bar's left unit only
    sim.move_object("b1", (x, y, sim.object_pose("b1")[2], 0.0, 0.0, yaw))
    sim.settle(60)
    bar = ("at", "b5", "1.5", "1")
    world.apply_symbolic([bar], [])
    observed = PerceivedState(seed=0, noise=SensingNoise.perfect()).bt_meta_observe(world, None)
    assert bar not in observed["symbolic_state"]
    world.apply_symbolic([], [bar])


def test_gripper_at_an_absolute_pose_is_sensed_and_an_object_relative_one_is_not_judged():
    from bt_meta.campaign.episode import variant_world
    from bt_meta.campaign.families import family
    from bt_meta.sensing.noise import SensingNoise
    from bt_meta.sensing.perceived import PerceivedState
    from bt_meta.world.simulation.scenes import load_scene

    _, _, world = variant_world(family("magnetic").task_path(), "nominal", load_scene("magnetic_attach").path,
                                None, 0)
    try:
        plugin = PerceivedState(seed=0, noise=SensingNoise.perfect())
        world.apply_symbolic([("at", "staging"), ("at", "active_above")], [("at", "home")])
        observed = plugin.bt_meta_observe(world, None)["symbolic_state"]
        assert ("at", "staging") not in observed  # the gripper is at home, far from the staging pose
        assert ("at", "active_above") in observed  # relative to the part: not judged, the belief stays
    finally:
        world.close()
