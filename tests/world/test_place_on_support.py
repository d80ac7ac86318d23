"""Place on any support (issue 31): a grounding frame's ``support:`` (a tray, a fixture, the part to stack on) gives the
height a placed part rests at -- the top of the support under the target, collision-checked like the table --
and a support that is not under the frame's anchor is a located error when the world is built. Hand-built scenes:
the letter A's blocks with a 1 cm tray under the letter (an obstacle, and a static catalogue object), and a block
stacked on another, on the Baxter and on the Panda (slow)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bt_meta.errors import ConfigError
from bt_meta.resources import trees_dir
from bt_meta.world.base import SUCCESS
from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

TRAY_TYPES = """\
types:
  tray_plate:
    description: A 30 x 30 cm plate 1 cm thick, fixed to the table
    shape: box
    size: [0.30, 0.30, 0.01]
    mass: 0
    colour: grey
    features:
      top: {point: [0.0, 0.0, 0.005], normal: [0.0, 0.0, 1.0]}
    grasp_frames:
      top: [0.0, 0.0, 0.009, 180, 0, 180]
"""

# The tray's centre sits 2 lb up the letter from its origin (robot x + 0.12): every cell of the letter is over it.
TRAY_OBSTACLE = ("obstacles:\n"
                 "  - {name: tray, shape: box, size: [0.30, 0.30, 0.01], pose: [0.67, 0.04, table, 0, 0, 0]}\n")
TRAY_OBJECT = "  - {name: tray, type: tray_plate, pose: [0.67, 0.04, table, 0, 0, 0]}\n"


def _scene(tmp_path: Path, *, obstacle: bool, stacked: bool = False, tray_at: str = "0.67, 0.04") -> Path:
    (tmp_path / "trays.yaml").write_text(TRAY_TYPES)
    text = (trees_dir() / "scenes" / "letters_A.yaml").read_text(encoding="utf-8")
    text = text.replace("scene: letters_A", "scene: tray_A\ncatalogue: [trays.yaml]")
    if stacked:  # b1 stands on the letter's origin cell: the part b0 goes on
        text = text.replace("{name: b1, type: megablok_1x1, colour: blue, pose: [0.64, -0.31, table, 0, 0, 0]}",
                            "{name: b1, type: megablok_1x1, colour: blue, pose: [0.55, 0.10, table, 0, 0, 0]}")
    elif obstacle:
        text = text.replace("variants:\n", TRAY_OBSTACLE.replace("0.67, 0.04", tray_at) + "variants:\n", 1)
    else:
        text = text.replace("objects:\n", "objects:\n" + TRAY_OBJECT.replace("0.67, 0.04", tray_at), 1)
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    return path


def _grounding(tmp_path: Path, support: str | None) -> Path:
    text = (trees_dir() / "poses" / "letters.yaml").read_text(encoding="utf-8")
    entry = "letter: {anchor: letter_origin, unit: 0.061}"
    assert entry in text
    if support is not None:
        text = text.replace(entry, f"letter: {{anchor: letter_origin, unit: 0.061, support: {support}}}")
    path = tmp_path / "poses" / "letters.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)
    return path


def _world(tmp_path: Path, scene: Path, support: str | None, robot: str = "baxter") -> SimWorld:
    with quiet_stdout():
        return SimWorld.from_task_file(trees_dir() / "letters.yaml", "A", robot=robot, scene=scene,
                                       grounding=_grounding(tmp_path, support))


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "obstacle"), [("baxter", True), ("baxter", False), ("panda", True)])
def test_a_block_is_placed_on_the_tray_under_its_cell(tmp_path: Path, robot: str, obstacle: bool, place):
    world = _world(tmp_path, _scene(tmp_path, obstacle=obstacle), "tray", robot)
    try:
        table = world.sim.table.top_z
        skill = place(world, "b0", "0", "0")
        assert skill.outcome == SUCCESS, skill.failure
        assert world.object_lowest("b0") == pytest.approx(table + 0.01, abs=0.003)  # on the tray, not in it
        assert skill.info["placement_error"] < 0.01
        skill = place(world, "b1", "1", "0")  # beside it, on the tray too
        assert skill.outcome == SUCCESS, skill.failure
        assert world.object_lowest("b1") == pytest.approx(table + 0.01, abs=0.003)
    finally:
        world.close()


@pytest.mark.slow
def test_without_the_support_the_tray_is_in_the_way(tmp_path: Path, place):
    """The same scene, the frame naming no support: the block is put down at the table's height, into the tray --
    the collision the support's height avoids."""
    world = _world(tmp_path, _scene(tmp_path, obstacle=False), None)
    try:
        skill = place(world, "b0", "0", "0")
        assert skill.outcome == "FAILURE"
        assert skill.failure.kind == "collision"
        assert "tray" in skill.failure.evidence["objects"]
    finally:
        world.close()


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["baxter", "panda"])
def test_a_block_is_stacked_on_the_part_under_its_cell(tmp_path: Path, robot: str, place):
    world = _world(tmp_path, _scene(tmp_path, obstacle=False, stacked=True), "b1", robot)
    try:
        top = world.object_top("b1")
        skill = place(world, "b0", "0", "0")
        assert skill.outcome == SUCCESS, skill.failure
        assert world.object_lowest("b0") == pytest.approx(top, abs=0.004)  # on b1's studs
        b0, b1 = world.sim.object_transform("b0"), world.sim.object_transform("b1")
        assert abs(b0[0, 3] - b1[0, 3]) < 0.01 and abs(b0[1, 3] - b1[1, 3]) < 0.01
    finally:
        world.close()


def _line_of(path: Path, text: str) -> tuple[int, int]:
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if text in line:
            return number, line.index(text) + 1
    raise AssertionError(text)


@pytest.mark.slow
@pytest.mark.parametrize(("support", "tray_at", "message"), [
    ("tray", "0.30, -0.30", r"'tray' \(at x 0.300, y -0.300\) is not under the frame's anchor 'letter_origin'"),
    ("shelf", "0.67, 0.04", r"the scene 'tray_A' has no object or obstacle 'shelf'"),
])
def test_a_support_not_under_the_target_is_a_located_error_at_world_build(tmp_path: Path, support: str,
                                                                          tray_at: str, message: str):
    scene = _scene(tmp_path, obstacle=True, tray_at=tray_at)
    grounding = _grounding(tmp_path, support)
    line, column = _line_of(grounding, f"support: {support}")
    with pytest.raises(ConfigError, match=message) as info:
        _world(tmp_path, scene, support)
    assert str(info.value).startswith(f"{grounding}:{line}:{column + len('support: ')}: frames.letter.support")
