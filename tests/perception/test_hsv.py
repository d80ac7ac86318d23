"""HSV blob detection: synthetic top views with exact answers, then real simulator top views (slow)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.perception.hsv import (
    DEFAULT_THRESHOLDS,
    ColourRange,
    HSVThresholds,
    PerceptionConfigError,
    PlaneProjection,
    classify_shape,
    colour_masks,
    detect_blocks,
)
from bt_meta.perception.synthetic import BLOCK_RGB, blank, draw_block, top_view_projection
from bt_meta.world.simulation.objects import LB

MPP = 0.0025


def view() -> PlaneProjection:
    return top_view_projection()


def canvas() -> np.ndarray:
    return blank(top_view_projection())


def angle_error(a: float, b: float, period: float) -> float:
    d = (a - b) % period
    return min(d, period - d)


SCENE = [
    (0.55, -0.35, 0.3, "1x2", "red"),
    (0.72, -0.05, 0.0, "1x1", "blue"),
    (0.62, -0.20, 0.7, "1x1", "red"),
    (0.85, -0.40, -1.2, "1x2", "blue"),
    (0.90, 0.05, math.pi / 2, "1x2", "red"),
]


def test_synthetic_blocks_found_with_exact_colour_shape_centroid_and_orientation():
    projection = view()
    image = canvas()
    for x, y, yaw, shape, colour in SCENE:
        draw_block(image, projection, x, y, yaw, shape, colour)
    blocks = detect_blocks(image, projection)
    assert len(blocks) == len(SCENE)
    for x, y, yaw, shape, colour in SCENE:
        block = min(blocks, key=lambda b: math.hypot(b.centroid[0] - x, b.centroid[1] - y))
        assert (block.colour, block.shape) == (colour, shape)
        assert math.hypot(block.centroid[0] - x, block.centroid[1] - y) < 0.001  # under half a pixel
        period = math.pi if shape == "1x2" else math.pi / 2
        assert angle_error(block.orientation, yaw, period) < math.radians(3)
        assert abs(block.width - LB) < 0.004
    assert [b.index for b in blocks] == list(range(len(SCENE)))
    assert blocks[0].label.startswith("b0=<")


def test_orientation_ranges_and_unknown_merged_blob():
    projection = view()
    image = canvas()
    draw_block(image, projection, 0.70, -0.20, math.radians(100), "1x2", "blue")
    # two red 1x2 side by side along their long axis: one 4 lb blob, no known shape
    draw_block(image, projection, 0.60, -0.45, 0.0, "1x2", "red")
    draw_block(image, projection, 0.60 + 2 * LB, -0.45, 0.0, "1x2", "red")
    blocks = detect_blocks(image, projection)
    by_colour = {b.colour: b for b in blocks}
    assert -math.pi / 2 < by_colour["blue"].orientation <= math.pi / 2
    assert angle_error(by_colour["blue"].orientation, math.radians(100), math.pi) < math.radians(3)
    assert by_colour["red"].shape == "unknown"


def test_other_colours_and_specks_are_ignored():
    projection = view()
    image = canvas()
    draw_block(image, projection, 0.70, -0.20, 0.0, "1x1", "green")
    image[10:13, 10:13] = BLOCK_RGB["red"]  # 9 pixels: a speck, not a block
    assert detect_blocks(image, projection) == []


def test_plane_projection_round_trip_and_camera_agreement():
    projection = view()
    xs, ys = np.array([0.55, 0.80, 0.70]), np.array([-0.40, 0.05, -0.20])
    us, vs = projection.table_to_pixel(xs, ys)
    back = projection.pixel_to_table(us, vs)
    assert np.allclose(back[0], xs) and np.allclose(back[1], ys)
    # the image centre looks at the centre, image up is +x, image right is -y
    assert np.allclose(projection.table_to_pixel(np.array([0.70]), np.array([-0.20])), ([160.0], [120.0]))
    u, v = projection.table_to_pixel(np.array([0.70 + MPP]), np.array([-0.20 - MPP]))
    assert np.allclose([u[0], v[0]], [161.0, 119.0])


def test_classify_shape_against_lb():
    assert classify_shape(LB, LB) == "1x1"
    assert classify_shape(2 * LB, LB) == "1x2"
    assert classify_shape(4 * LB, LB) == "unknown"
    assert classify_shape(2 * LB, 2 * LB) == "unknown"
    assert classify_shape(1.4 * LB, LB) == "1x1"


def test_thresholds_from_mapping_and_errors():
    thresholds = HSVThresholds.from_mapping(
        {"colours": {"green": [[[40, 100, 50], [80, 255, 255]]]}, "min_pixels": 5})
    projection = view()
    image = canvas()
    draw_block(image, projection, 0.70, -0.20, 0.0, "1x1", "green")
    blocks = detect_blocks(image, projection, thresholds=thresholds)
    assert [(b.colour, b.shape) for b in blocks] == [("green", "1x1")]
    assert thresholds.code("green") == 1 and DEFAULT_THRESHOLDS.code("blue") == 2
    with pytest.raises(PerceptionConfigError, match=r"h = 200 is outside 0\.\.179"):
        ColourRange((200, 0, 0), (10, 255, 255))
    with pytest.raises(PerceptionConfigError, match=r"lower .* exceeds upper"):
        ColourRange((50, 0, 0), (10, 255, 255))
    with pytest.raises(PerceptionConfigError, match=r"thresholds\.yaml: HSV thresholds, colour 'red'"):
        HSVThresholds.from_mapping({"colours": {"red": [[1, 2]]}}, path="thresholds.yaml")
    with pytest.raises(PerceptionConfigError, match="unknown keys \\['hue'\\]"):
        HSVThresholds.from_mapping({"colours": {}, "hue": 3})
    with pytest.raises(PerceptionConfigError, match="at least one colour"):
        HSVThresholds({})
    with pytest.raises(ValueError, match="H x W x 3 uint8"):
        colour_masks(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="projection is 320x240"):
        detect_blocks(np.zeros((10, 10, 3), np.uint8), projection)


# -- the simulator's top view ------------------------------------------------------------------------------------

SIM_BLOCKS = {
    "b0": ("1x2", "red", (0.55, -0.35, 0.3)),
    "b1": ("1x1", "blue", (0.72, -0.05, 0.0)),
    "b2": ("1x1", "red", (0.62, -0.20, 0.7)),
    "b3": ("1x2", "blue", (0.88, -0.45, -1.2)),
    "b4": ("1x1", "blue", (0.50, -0.55, 0.4)),
    "b5": ("1x2", "red", (0.92, 0.10, 1.5)),
}


@pytest.fixture(scope="module")
def sim_view():
    from bt_meta.world.simulation.camera import TopViewCamera
    from bt_meta.world.simulation.objects import megablok
    from bt_meta.world.simulation.sim import Simulation

    with Simulation(seed=0) as sim:
        for name, (shape, colour, (x, y, yaw)) in SIM_BLOCKS.items():
            sim.spawn(name, megablok(shape, colour), (x, y, 0.0, 0.0, 0.0, yaw), on_table=True)
        sim.settle(120)
        image = TopViewCamera(sim).capture()
        truth = {name: sim.object_state(name) for name in SIM_BLOCKS}
        yield image, truth, sim.table.top_z


@pytest.mark.slow
@pytest.mark.parametrize("use_depth", [True, False])
def test_simulator_top_view_every_block_found(sim_view, use_depth):
    image, truth, table_z = sim_view
    body_top = table_z + 0.6 * LB
    # Without depth, pixels go onto the plane of the blocks' top face (known block height).
    projection = PlaneProjection.from_image(image, table_z if use_depth else body_top)
    blocks = detect_blocks(image.rgb, projection, depth=image.depth if use_depth else None)
    assert len(blocks) == len(SIM_BLOCKS)
    tolerance = 0.003 if use_depth else 0.008  # without depth the visible side faces pull
    for name, (shape, colour, _) in SIM_BLOCKS.items():
        state = truth[name]
        block = min(blocks, key=lambda b: math.hypot(b.centroid[0] - state.pose[0], b.centroid[1] - state.pose[1]))
        assert (block.colour, block.shape) == (colour, shape), name
        assert math.hypot(block.centroid[0] - state.pose[0], block.centroid[1] - state.pose[1]) < tolerance, name
        period = math.pi if shape == "1x2" else math.pi / 2
        assert angle_error(block.orientation, state.pose[5], period) < math.radians(4), name
        if use_depth:
            assert abs(block.top_z - body_top) < 0.004
