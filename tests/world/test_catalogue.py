"""The object catalogue: shipped entries (the paper's object 2 among them), a user's file extending it through a
scene, and located errors for entries without their frames."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from bt_meta.errors import ConfigError
from bt_meta.world.simulation.catalogue import catalogue_path, load_catalogue, object_types, shipped_catalogue
from bt_meta.world.simulation.scenes import load_scene

MINE = """\
types:
  block_long:
    shape: box
    size: [0.12, 0.03, 0.03]
    mass: 0.04
    colour: green
    friction: 1.1
    features:
      end: {point: [0.06, 0, 0], normal: [1, 0, 0]}
      bottom: {point: [0, 0, -0.015], normal: [0, 0, -1]}
    primary: bottom
    grasp_frames:
      middle: [0, 0, 0.019, 180, 0, 90]
"""


def write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def test_object_2_is_a_shipped_catalogue_entry():
    entry = shipped_catalogue()["magnet_active_side"]
    model = entry.model()
    assert model.type == "magnet_active_side" and model.colour == "orange" and model.role == "active"
    assert model.feature().name == "magnet" and model.feature().normal == (-1.0, 0.0, 0.0)
    low, high = model.extent()
    assert (high - low) == pytest.approx([0.06, 0.04, 0.04])
    assert entry.grasp_frames["top"][2] == pytest.approx(0.024)
    assert {"magnet_active_side", "cube_5cm", "can"} <= set(object_types())
    assert "megablok_1x2" in object_types()  # the code-built types stay


def test_a_users_file_extends_the_catalogue_through_a_scene(tmp_path):
    write(tmp_path / "mine.yaml", MINE)
    scene = write(tmp_path / "scene.yaml", """\
        scene: mine
        catalogue: [mine.yaml]
        objects:
          - {name: stick, type: block_long, pose: [0.6, -0.3, table, 0, 0, 0]}
          - {name: can, type: can, colour: blue, pose: [0.7, -0.3, table, 0, 0, 0]}
        """)
    loaded = load_scene(scene)
    stick, can = (o.model() for o in loaded.objects)
    assert stick.type == "block_long" and stick.colour == "green" and stick.lateral_friction == 1.1
    assert stick.feature().name == "bottom" and stick.feature("end").normal == (1.0, 0.0, 0.0)
    assert can.colour == "blue" and can.parts[0].radius == pytest.approx(0.033)


def test_rolling_friction_follows_the_shape_unless_the_entry_gives_it(tmp_path):
    """A round part gets rolling friction by default (lying on its side it would roll on its own); a part resting
    on flat faces none; an entry's own value wins, and a negative one fails at its line."""
    assert shipped_catalogue()["can"].model().rolling_friction == pytest.approx(0.001)
    assert shipped_catalogue()["cube_5cm"].model().rolling_friction == 0.0
    path = write(tmp_path / "mine.yaml", MINE.replace("    friction: 1.1\n", "    friction: 1.1\n"
                                                      "    rolling_friction: 0.004\n    spinning_friction: 0.002\n"))
    stick = load_catalogue(path)["block_long"].model()
    assert stick.rolling_friction == pytest.approx(0.004) and stick.spinning_friction == pytest.approx(0.002)
    write(path, MINE.replace("    friction: 1.1\n", "    friction: 1.1\n    rolling_friction: -0.1\n"))
    with pytest.raises(ConfigError, match=r"mine.yaml:8:23: type 'block_long': rolling_friction must be at least 0"):
        load_catalogue(path)


@pytest.mark.parametrize(
    ("old", "new", "needle", "message"),
    [
        ("    grasp_frames:\n      middle: [0, 0, 0.019, 180, 0, 90]\n", "", "block_long:",
         "type 'block_long': missing key 'grasp_frames' (where a gripper may hold it)"),
        ("    features:\n      end: {point: [0.06, 0, 0], normal: [1, 0, 0]}\n"
         "      bottom: {point: [0, 0, -0.015], normal: [0, 0, -1]}\n    primary: bottom\n", "", "block_long:",
         "type 'block_long': missing key 'features' (its attachment points and normals, AP/AN)"),
        ("shape: box", "shape: torus", "torus", "type 'block_long': unknown shape 'torus'; known: box, cylinder, mesh"),
        ("normal: [1, 0, 0]", "normal: [1, 1, 0]", "[1, 1, 0]",
         "feature 'end': the normal must be a unit vector (length 1.4142)"),
        ("[0, 0, 0.019, 180, 0, 90]", "[0, 0, 0.019]", "[0, 0, 0.019]",
         "grasp frame 'middle' must be [x, y, z, roll, pitch, yaw] (m, degrees)"),
    ],
)
def test_bad_entries_fail_at_their_line(tmp_path, old, new, needle, message):
    assert old in MINE
    path = write(tmp_path / "mine.yaml", MINE.replace(old, new, 1))
    line, text = next((n, t) for n, t in enumerate(path.read_text().splitlines(), 1) if needle in t)
    with pytest.raises(ConfigError) as info:
        load_catalogue(path)
    column = text.index(needle) + 1 if needle != "block_long:" else text.index("block_long:") + 1
    expected = f"{path}:{line}:{column}: {message}"
    if needle == "block_long:":  # a missing key is located at the entry's mapping, one line below its name
        expected = f"{path}:{line + 1}:5: {message}"
    assert str(info.value) == expected


def test_a_user_type_may_not_shadow_a_shipped_one(tmp_path):
    path = write(tmp_path / "mine.yaml", MINE.replace("block_long:", "cube_5cm:"))
    with pytest.raises(ConfigError, match="object type 'cube_5cm' is already defined"):
        object_types([path])
    assert catalogue_path().is_file()
