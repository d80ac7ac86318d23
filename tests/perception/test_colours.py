"""Thresholds derived from the declared colours: every colour the scene format accepts is seen, as itself.

Synthetic top views per colour (fully lit and, for the chromatic colours, under a dimmer light), then the
simulator's own rendering of one block of every colour (slow).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.perception.colours import hsv_of, scene_thresholds, thresholds_for
from bt_meta.perception.hsv import DEFAULT_THRESHOLDS, PerceptionConfigError, detect_blocks
from bt_meta.perception.synthetic import TABLE_RGB, blank, draw_block, top_view_projection
from bt_meta.world.simulation.objects import COLOURS

TABLE = tuple(c / 255 for c in TABLE_RGB)
CHROMATIC = [name for name, rgba in COLOURS.items() if hsv_of(rgba)[1] >= 90]


def scene_of(colour: str, light: float = 1.0) -> np.ndarray:
    projection = top_view_projection()
    image = blank(projection)
    draw_block(image, projection, 0.62, -0.25, 0.3, "1x1", colour)
    draw_block(image, projection, 0.80, -0.10, -0.5, "1x2", colour)
    mask = np.any(image != np.array(TABLE_RGB, np.uint8), axis=2)
    image[mask] = np.clip(image[mask].astype(float) * light, 0, 255).astype(np.uint8)
    return image


@pytest.mark.parametrize("colour", list(COLOURS))
def test_every_declared_colour_is_seen_as_itself(colour):
    blocks = detect_blocks(scene_of(colour), top_view_projection(), thresholds=scene_thresholds(TABLE))
    assert sorted((b.colour, b.shape) for b in blocks) == [(colour, "1x1"), (colour, "1x2")]


@pytest.mark.parametrize("colour", CHROMATIC)
def test_chromatic_colours_are_seen_under_a_dimmer_light(colour):
    blocks = detect_blocks(scene_of(colour, light=0.55), top_view_projection(), thresholds=scene_thresholds(TABLE))
    assert sorted((b.colour, b.shape) for b in blocks) == [(colour, "1x1"), (colour, "1x2")]


def test_the_table_is_never_a_block_and_the_paper_colours_keep_their_codes():
    thresholds = scene_thresholds(TABLE)
    assert detect_blocks(blank(top_view_projection()), top_view_projection(), thresholds=thresholds) == []
    assert thresholds.names[:2] == ("red", "blue") and set(thresholds.names) == set(COLOURS)
    assert (thresholds.code("red"), thresholds.code("blue")) == (1, 2)


def test_the_hand_tuned_thresholds_were_blind_to_the_other_colours():
    blind = [c for c in COLOURS if not detect_blocks(scene_of(c), top_view_projection())]
    assert set(blind) == set(COLOURS) - {"red", "blue"} and DEFAULT_THRESHOLDS.names == ("red", "blue")


def test_colours_that_cannot_be_told_apart_are_an_error():
    with pytest.raises(PerceptionConfigError, match="colours 'red' and 'crimson' have the same hue"):
        thresholds_for({"red": (0.9, 0.1, 0.1), "crimson": (0.5, 0.05, 0.05)})
    with pytest.raises(PerceptionConfigError, match=r"a colour must be 3 \(or 4\) numbers in 0\.\.1"):
        thresholds_for({"red": (2.0, 0.1, 0.1)})
    with pytest.raises(PerceptionConfigError, match="at least one colour"):
        thresholds_for({})


@pytest.mark.slow
def test_the_simulator_renders_every_declared_colour_and_perception_sees_it():
    import bt_meta_plugins.camera_perception as camera_plugin

    from bt_meta.world.simulation.camera import TopViewCamera
    from bt_meta.world.simulation.objects import megablok
    from bt_meta.world.simulation.sim import Simulation

    names = list(COLOURS)
    with Simulation(seed=0) as sim:
        places = {}
        for index, colour in enumerate(names):
            x, y = 0.50 + 0.13 * (index % 4), -0.45 + 0.15 * (index // 4)
            places[colour] = (x, y)
            sim.spawn(f"b_{colour}", megablok("1x1", colour), (x, y, 0.0, 0.0, 0.0, 0.0), on_table=True)
        sim.settle(60)
        image = TopViewCamera(sim).capture()
        thresholds = camera_plugin.CameraPerception().thresholds_for(type("W", (), {"sim": sim})())
        from bt_meta.perception.hsv import PlaneProjection

        blocks = detect_blocks(image.rgb, PlaneProjection.from_image(image, sim.table.top_z), depth=image.depth,
                               thresholds=thresholds)
    for colour, (x, y) in places.items():
        near = [b for b in blocks if math.hypot(b.centroid[0] - x, b.centroid[1] - y) < 0.02]
        assert [(b.colour, b.shape) for b in near] == [(colour, "1x1")], (colour, [b.colour for b in blocks])
    assert len(blocks) == len(names), [(b.colour, b.shape, b.centroid) for b in blocks]


def lit_and_noisy(colour: str, seed: int) -> np.ndarray:
    """``scene_of(colour)`` as the perceived world's camera gives it: a frame's lighting gain and white balance
    (the whole image, table included) and pixel noise, drawn by :func:`bt_meta.sensing.noise.corrupt_image`."""
    from bt_meta.sensing.noise import SensingNoise, corrupt_image
    from bt_meta.world.simulation.camera import CameraImage

    image = CameraImage(scene_of(colour), None, None, None, np.eye(4))  # type: ignore[arg-type]
    return corrupt_image(image, SensingNoise(), SensingNoise.rng(seed, 2, 0), np.eye(4)).rgb


@pytest.mark.parametrize("colour", list(COLOURS))
def test_every_declared_colour_is_seen_under_the_perceived_worlds_lighting_once_balanced(colour):
    from bt_meta.perception.colours import balance_to_background

    thresholds = scene_thresholds(TABLE)
    judged = 0
    for seed in range(8):
        frame = lit_and_noisy(colour, seed)
        if colour == "white" and np.median(frame.reshape(-1, 3), axis=0).max() >= 250:
            continue  # over-exposed: the table clipped to the white block's 255, nothing can tell them apart
        judged += 1
        blocks = detect_blocks(balance_to_background(frame, TABLE), top_view_projection(), thresholds=thresholds)
        assert sorted((b.colour, b.shape) for b in blocks) == [(colour, "1x1"), (colour, "1x2")], (seed, blocks)
    assert judged >= 6


def test_without_balancing_a_dim_frame_shows_a_grey_as_another_grey():
    """The greys are told by value, which a lighting gain scales: why the perceived world balances each frame."""
    from bt_meta.perception.colours import balance_to_background

    thresholds = scene_thresholds(TABLE)
    image = scene_of("white")
    dim = (image.astype(float) * 0.75).astype(np.uint8)  # the whole frame, table included
    assert {b.colour for b in detect_blocks(dim, top_view_projection(), thresholds=thresholds)} != {"white"}
    balanced = balance_to_background(dim, TABLE)
    assert {b.colour for b in detect_blocks(balanced, top_view_projection(), thresholds=thresholds)} == {"white"}


def test_balancing_undoes_a_gain_and_refuses_what_is_not_an_image():
    from bt_meta.perception.colours import balance_to_background

    image = scene_of("blue")
    warm = np.clip(image.astype(float) * np.array([1.1, 1.0, 0.8]), 0, 255).astype(np.uint8)
    restored = balance_to_background(warm, TABLE)
    assert np.abs(restored.astype(int) - image.astype(int)).max() <= 3
    with pytest.raises(ValueError, match="uint8 RGB image"):
        balance_to_background(image.astype(float), TABLE)


@pytest.mark.parametrize("other", [c for c in COLOURS if c != "blue"])
def test_a_block_touching_one_of_another_colour_stays_a_block_of_its_own(other):
    """Touching blocks of different colours are two blobs with their own shape and centroid (one mask per colour);
    the grid-map monitor labels its cells one colour at a time too."""
    from bt_meta.world.simulation.objects import LB

    projection = top_view_projection()
    image = blank(projection)
    draw_block(image, projection, 0.70, -0.20, 0.0, "1x1", "blue")
    draw_block(image, projection, 0.70 + 1.5 * LB, -0.20, 0.0, "1x2", other)  # end to end, no gap
    blocks = detect_blocks(image, projection, thresholds=scene_thresholds(TABLE))
    assert sorted((b.colour, b.shape) for b in blocks) == sorted([("blue", "1x1"), (other, "1x2")])
    blue = next(b for b in blocks if b.colour == "blue")
    assert math.hypot(blue.centroid[0] - 0.70, blue.centroid[1] + 0.20) < 0.003
