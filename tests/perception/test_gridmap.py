"""Grid-maps: a 1x2 block against two 1x1 blocks, colour codes, crops; synthetic and simulator top views."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bt_meta.memory import GridMap
from bt_meta.perception.gridmap import (
    DEFAULT_SPEC,
    GridSpec,
    block_grid_maps,
    grid_difference,
    grid_map_at,
    occupancy,
    render,
    table_crop,
)
from bt_meta.perception.hsv import PerceptionConfigError, PlaneProjection, detect_blocks
from bt_meta.perception.synthetic import blank, draw_block, top_view_projection
from bt_meta.perception.topview import analyse
from bt_meta.world.simulation.objects import LB

CENTRE = (0.70, -0.20)


def one_1x2(colour: str = "blue") -> tuple[np.ndarray, PlaneProjection]:
    projection = top_view_projection()
    image = blank(top_view_projection())
    draw_block(image, projection, *CENTRE, 0.0, "1x2", colour)  # long axis along +x: image up
    return image, projection


def two_1x1(colours: tuple[str, str] = ("blue", "blue")) -> tuple[np.ndarray, PlaneProjection]:
    projection = top_view_projection()
    image = blank(top_view_projection())
    draw_block(image, projection, CENTRE[0] + LB / 2, CENTRE[1], 0.0, "1x1", colours[0])
    draw_block(image, projection, CENTRE[0] - LB / 2 - 0.008, CENTRE[1], 0.0, "1x1", colours[1])  # 8 mm apart
    return image, projection


def test_spec_is_the_papers_grid():
    assert DEFAULT_SPEC.cells == 6
    assert DEFAULT_SPEC.window == pytest.approx(3 * LB)
    assert DEFAULT_SPEC.cell_size == pytest.approx(0.5 * LB)
    with pytest.raises(PerceptionConfigError, match="fill fraction"):
        GridSpec(fill=0.0)
    with pytest.raises(PerceptionConfigError, match="cell size must be positive"):
        GridSpec(cell_size=-1.0)


def test_grid_map_of_a_1x2_block_is_its_footprint():
    image, projection = one_1x2()
    grid = grid_map_at(image, projection, CENTRE, object_name="b5", colour="blue", shape="1x2")
    assert isinstance(grid, GridMap)
    assert render(grid) == "\n".join(["......", "..bb..", "..bb..", "..bb..", "..bb..", "......"])
    assert grid.occupancy.shape == (6, 6) and grid.centroid == CENTRE
    crop = grid.image_array()
    assert crop.shape == (48, 48, 3)  # the 3 lb crop, 8 pixels per cell, BGR
    assert crop[24, 24].tolist() == [217, 51, 20]


def test_two_1x1_blocks_differ_from_one_1x2_only_in_the_blobs_not_the_grid():
    """Two touching-size 1x1 blocks fill the same cells as one 1x2 (the paper's H bar matches A's bar by form),
    while blob detection tells them apart."""
    bar, projection = one_1x2()
    pair, _ = two_1x1()
    blocks_bar = detect_blocks(bar, projection)
    blocks_pair = detect_blocks(pair, projection)
    assert [b.shape for b in blocks_bar] == ["1x2"]
    assert [b.shape for b in blocks_pair] == ["1x1", "1x1"]
    grid_bar = grid_map_at(bar, projection, CENTRE)
    grid_pair = grid_map_at(pair, projection, CENTRE)
    assert grid_difference(grid_bar, grid_pair) == 0
    # centred on one of the 1x1 blocks (as the paper crops a blob), the grid is shifted by one block
    one = grid_map_at(pair, projection, blocks_pair[0].centroid)
    assert grid_difference(grid_bar, one) == 4


def test_single_1x1_replacing_the_1x2_is_four_cells_off_and_rotation_is_optional():
    bar, projection = one_1x2()
    single = blank(top_view_projection())
    draw_block(single, projection, *CENTRE, 0.0, "1x1", "blue")
    assert grid_difference(grid_map_at(bar, projection, CENTRE), grid_map_at(single, projection, CENTRE)) == 4
    turned = blank(top_view_projection())
    draw_block(turned, projection, *CENTRE, math.pi / 2, "1x2", "blue")
    a, b = grid_map_at(bar, projection, CENTRE), grid_map_at(turned, projection, CENTRE)
    assert grid_difference(a, b) == 8
    assert grid_difference(a, b, rotations=True) == 0


def test_colour_codes_and_mixed_pair():
    pair, projection = two_1x1(("red", "blue"))
    grid = grid_map_at(pair, projection, CENTRE)
    assert render(grid) == "\n".join(["......", "..rr..", "..rr..", "..bb..", "..bb..", "......"])
    assert set(np.unique(grid.occupancy)) == {0, 1, 2}


def test_block_grid_maps_name_and_centre_each_block_and_context_counts():
    projection = top_view_projection()
    image = blank(top_view_projection())
    draw_block(image, projection, *CENTRE, 0.0, "1x1", "red")
    draw_block(image, projection, CENTRE[0], CENTRE[1] - 1.5 * LB, 0.0, "1x1", "blue")  # neighbour to the right
    blocks = detect_blocks(image, projection)
    maps = block_grid_maps(image, projection, blocks)
    by_colour = {m.colour: m for m in maps}
    assert by_colour["red"].object_name.startswith("b")
    assert render(by_colour["red"]) == "\n".join(["......", "......", "..rr.b", "..rr.b", "......", "......"])
    with pytest.raises(ValueError, match="2 blocks"):
        block_grid_maps(image, projection, blocks, names=["x"])
    view_ = analyse(image, projection, namer=lambda b: f"obj{b.index}")
    assert [m.object_name for m in view_.grid_maps] == ["obj0", "obj1"]
    assert view_.block_near(CENTRE, 0.01).colour == "red"


def test_crop_outside_the_image_is_empty_and_shape_errors():
    projection = top_view_projection()
    image = blank(top_view_projection())
    far = table_crop(image, projection, (5.0, 5.0))
    assert far.shape == (48, 48, 3) and not far.any()
    with pytest.raises(ValueError, match="crop is"):
        occupancy(np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(ValueError, match="different shapes"):
        grid_difference(np.zeros((6, 6)), np.zeros((4, 4)))


@pytest.mark.slow
def test_simulator_grid_maps_of_a_1x2_and_two_1x1():
    from bt_meta.perception.topview import capture
    from bt_meta.world.simulation.camera import TopViewCamera
    from bt_meta.world.simulation.objects import megablok
    from bt_meta.world.simulation.sim import Simulation

    with Simulation(seed=0) as sim:
        sim.spawn("bar", megablok("1x2", "blue"), (0.60, -0.35, 0, 0, 0, 0), on_table=True)
        sim.spawn("p0", megablok("1x1", "red"), (0.80 + LB / 2 + 0.004, -0.05, 0, 0, 0, 0), on_table=True)
        sim.spawn("p1", megablok("1x1", "red"), (0.80 - LB / 2 - 0.004, -0.05, 0, 0, 0, 0), on_table=True)
        sim.settle(120)
        top = capture(TopViewCamera(sim))
        assert sorted((b.colour, b.shape) for b in top.blocks) == [("blue", "1x2"), ("red", "1x1"), ("red", "1x1")]
        bar = next(m for m in top.grid_maps if m.shape == "1x2")
        assert render(bar) == "\n".join(["......", "..bb..", "..bb..", "..bb..", "..bb..", "......"])
        pair = top.grid_map_at((0.80, -0.05))
        assert render(pair) == "\n".join(["......", "..rr..", "..rr..", "..rr..", "..rr..", "......"])
        assert grid_difference(bar, pair) == 0


@pytest.mark.slow
def test_a_tall_obstacle_in_view_does_not_shift_the_window_of_a_merged_letter():
    """A finished letter is one blob of unknown shape, so the apex window is read at a default height; with a
    18 cm post elsewhere in view the median of the two blobs' tops put it half-way up, and the perspective shifted
    the apex half a cell (generated letters_A s1 0011, a false alarm). The window is read at the surface the depth
    image shows over its centre."""
    from bt_meta.perception.colours import scene_thresholds
    from bt_meta.perception.topview import capture
    from bt_meta.world.simulation.camera import TopViewCamera
    from bt_meta.world.simulation.objects import megablok
    from bt_meta.world.simulation.obstacles import obstacle_model
    from bt_meta.world.simulation.sim import Simulation

    with Simulation(seed=0) as sim:
        bar = (0.611, 0.0085)
        sim.spawn("bar", megablok("1x2", "blue"), (*bar, 0, 0, 0, math.pi / 2), on_table=True)
        sim.spawn("apex", megablok("1x1", "blue"), (bar[0] + LB, bar[1], 0, 0, 0, 0), on_table=True)
        sim.add_obstacle("post", obstacle_model("post", {"radius": 0.054, "height": 0.18}),
                         (0.963, -0.371, sim.table.top_z, 0, 0, 0))
        sim.settle(120)
        top = capture(TopViewCamera(sim), thresholds=scene_thresholds(sim.table.colour))  # as camera_perception
        assert [b.shape for b in top.blocks if b.colour == "blue"] == ["unknown"]  # the letter is one blob
        post = next(b for b in top.blocks if b.colour != "blue")
        letter = next(b for b in top.blocks if b.colour == "blue")
        assert post.top_z - letter.top_z > 0.1
        apex = (bar[0] + LB, bar[1])
        assert top.surface_near(apex) == pytest.approx(letter.top_z, abs=0.002)
        assert render(top.grid_map_at(apex)) == render(top.grid_map_at(apex, z=letter.top_z))
        assert render(top.grid_map_at(apex)).split("\n")[2:4] == ["..bb..", "..bb.."]
        # where nothing lies, at the table; beside the post (its top over the window's edge), still at the block
        assert top.surface_near((0.45, -0.55)) == pytest.approx(sim.table.top_z, abs=0.003)
        assert top.surface_near((bar[0], bar[1] + LB / 2)) == pytest.approx(letter.top_z, abs=0.003)
