"""A grounding file of the wrong shape is one ConfigError naming the key (found by the loader fuzz campaign)."""

from __future__ import annotations

import pytest

from bt_meta.errors import ConfigError
from bt_meta.world.simulation.sim_world import load_grounding

BASE = "domain: letters\nproblems:\n  A: {scene: letters_A}\nskills:\n  place: {skill: place, frame: letter}\n"


@pytest.mark.parametrize(("extra", "message"), [
    ("frames:\n  letter\n", "'frames' must be a mapping of name -> mapping"),
    ("poses: [1, 2]\n", "'poses' must be a mapping of name -> mapping"),
    ("features: {f: 3}\n", "'features' must be a mapping of name -> mapping"),
    ("robot_pose: {left_s0: [1]}\n", "robot_pose: joint values are numbers (radians or metres)"),
    ("robot_pose: {left_s0: wide}\n", "robot_pose: joint values are numbers (radians or metres)"),
    ("robot_pose: {panda: {j1: wide}}\n", "robot_pose of panda: joint values are numbers (radians or metres)"),
    ("robot_pose: {panda: {j1: 1}, j2: 0.5}\n", "robot_pose mixes joint values and per-robot mappings: use one form"),
    ("robot_pose: [1, 2]\n", "robot_pose is a mapping: joint -> value, or robot name -> {joint: value}"),
    ("objects: {a: {b: c}}\n", "'objects' must be a mapping of name -> value"),
    ("frames: {x: !!int nope}\n", "YAML tag error: cannot read the !!int value 'nope': ValueError"),
    ("poses:\n  lift: {pose: [0.5, 0.1]}\n", "pose 'lift': give [x, y, z] (pointing down as the robot grasps) or "
                                          "[x, y, z, roll, pitch, yaw] (metres, degrees), not [0.5, 0.1]"),
    ("poses:\n  lift: {pose: [0.5, 0.1, up]}\n",
     "pose 'lift': give [x, y, z] (pointing down as the robot grasps) or [x, y, z, roll, pitch, yaw] (metres, "
     "degrees), not [0.5, 0.1, 'up']"),
])
def test_wrong_shapes(tmp_path, extra, message):
    path = tmp_path / "g.yaml"
    path.write_text(BASE + extra)
    with pytest.raises(ConfigError) as caught:
        load_grounding("letters", path=path)
    assert caught.value.message == message
    assert caught.value.path == str(path)


def test_the_shipped_shape_loads(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text(BASE + "robot_pose: {left_s0: 0.8}\nobjects: {b0: block_0}\n")
    grounding = load_grounding("letters", path=path)
    assert grounding.robot_pose == {"*": {"left_s0": 0.8}} and grounding.objects == {"b0": "block_0"}


def test_a_wrong_pose_names_its_line(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text(BASE + "poses:\n  home: {pose: [0.5, 0.1, 0.2]}\n  lift: {pose: [0.5, 0.1, 0.2, 180]}\n")
    with pytest.raises(ConfigError) as caught:
        load_grounding("letters", path=path)
    assert (caught.value.line, caught.value.column) == (8, 16)
