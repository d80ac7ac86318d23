"""Free spots (``bt_meta.world.simulation.free_spots``): the anchor when it is clear, the nearest clear point around
it when something lies there, never off the table, ``None`` when the table is full; and in the real simulator, a
housing on its side re-oriented over a set-down spot a spare block crowds (slow)."""

from __future__ import annotations

import json
import math
import textwrap

import numpy as np
import pytest

from bt_meta.world.simulation.free_spots import MARGIN, clearance, nearest_free_spot

TABLE = ((0.45, 1.05), (-0.65, 0.45))


def square(x: float, y: float, half: float = 0.016) -> np.ndarray:
    """The outline of a 1x1 block's footprint centred at (x, y)."""
    return np.array([[x + sx * half, y + sy * half] for sx in (-1, 1) for sy in (-1, 1)])


def test_a_clear_anchor_is_kept():
    assert nearest_free_spot((0.6, -0.3), 0.05, [square(0.8, 0.0)], TABLE) == (0.6, -0.3)
    assert nearest_free_spot((0.6, -0.3), 0.05, [], TABLE) == (0.6, -0.3)


def test_a_crowded_anchor_moves_to_the_nearest_spot_clear_of_every_footprint():
    blocks = [square(0.6, -0.27), square(0.63, -0.3)]
    spot = nearest_free_spot((0.6, -0.3), 0.05, blocks, TABLE)
    assert spot is not None and spot != (0.6, -0.3)
    assert clearance(spot, 0.05, blocks) >= MARGIN
    shift = math.dist(spot, (0.6, -0.3))
    assert shift <= 0.12
    # nothing nearer on the search's rings is clear: the first ring that has a clear point gave it
    for r in np.arange(0.02, shift - 1e-9, 0.02):
        for angle in np.linspace(0.0, 2 * math.pi, 16, endpoint=False):
            point = (0.6 + r * math.cos(angle), -0.3 + r * math.sin(angle))
            assert clearance(point, 0.05, blocks) < MARGIN


def test_inside_a_large_footprint_is_not_clear():
    """A board under the anchor: the points of its outline are far away, but the anchor lies inside it."""
    board = np.array([[0.5, -0.4], [0.8, -0.4], [0.8, -0.1], [0.5, -0.1]])
    assert clearance((0.65, -0.25), 0.03, [board]) < 0
    spot = nearest_free_spot((0.65, -0.25), 0.03, [board], TABLE, most=0.3)
    assert spot is not None and clearance(spot, 0.03, [board]) >= MARGIN


def test_a_spot_off_the_table_is_never_chosen_and_a_full_table_has_none():
    edge = ((0.45, 1.05), (-0.30, 0.45))
    spot = nearest_free_spot((0.6, -0.28), 0.05, [square(0.6, -0.25)], edge)
    assert spot is not None and spot[1] >= -0.30 + 0.05  # the nearer clear points hang over the edge
    assert clearance(spot, 0.05, [square(0.6, -0.25)]) >= MARGIN
    everything = np.array([[0.3, -0.8], [1.2, -0.8], [1.2, 0.6], [0.3, 0.6]])
    assert nearest_free_spot((0.6, -0.3), 0.05, [everything], TABLE) is None


CROWDED = """\
scene: housing_crowded_spot
anchors:
  set_down_spot: [0.50, -0.28, table, 0, 0, 0]
objects:
  - {name: board, type: task_board, pose: [0.62, -0.05, table, 0, 0, 0]}
  - {name: housing, type: housing, pose: [0.58, -0.38, table, 90, 0, 0]}
  - {name: spare_block, type: megablok_1x1, colour: red, pose: [0.505, -0.255, table, 0, 0, 40]}
"""


@pytest.mark.slow
def test_a_housing_is_re_oriented_clear_of_a_block_lying_by_the_set_down_spot(tmp_path, capsys):
    """The housing lies on its side; the repair turns it over the scene's set-down spot, where a spare block lies
    2.5 cm off the anchor. Let go at the anchor, the housing landed on the block and never stood up (generated
    housing variant 0011); set down at the nearest clear spot it stands, goes in, and the block is not touched."""
    from bt_meta.cli import main
    from bt_meta.resources import trees_dir

    scene = tmp_path / "scene.yaml"
    scene.write_text(textwrap.dedent(CROWDED), encoding="utf-8")
    memory = str(tmp_path / "memory.sqlite")
    task_file = str(trees_dir() / "housing_insertion.yaml")
    assert main(["record", task_file, "--problem", "nominal", "--memory", memory]) == 0
    capsys.readouterr()
    code = main(["run", task_file, "--problem", "nominal", "--scene", str(scene), "--repair", "--memory", memory,
                 "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0 and result["status"] == "SUCCESS", result["stop_reason"]
    assert any(a["proposal"]["plugin"] == "reorientation" for a in result["attempts"])
    block = result["objects"]["spare_block"]["pose"]
    assert math.dist(block[:2], (0.505, -0.255)) < 0.002  # not pushed
