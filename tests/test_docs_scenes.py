"""The examples in docs/scenes.md load: the scene file and the robot description are what the loaders accept."""

from __future__ import annotations

import re
from pathlib import Path

from bt_meta.world.robot.description import load_robot
from bt_meta.world.simulation.scenes import load_scene

DOC = Path(__file__).resolve().parents[1] / "docs" / "scenes.md"


def yaml_blocks() -> list[str]:
    return re.findall(r"^```yaml\n(.*?)^```$", DOC.read_text(encoding="utf-8"), re.M | re.S)


def test_the_scene_example_loads(tmp_path):
    (block,) = [b for b in yaml_blocks() if b.startswith("scene:")]
    path = tmp_path / "scene.yaml"
    path.write_text(block)
    scene = load_scene(path)
    assert [o.name for o in scene.objects] == ["base", "peg"]
    assert [o.name for o in scene.obstacles] == ["wall", "post"]
    assert [o.name for o in scene.objects_for("two_pegs")] == ["base", "peg", "peg2"]
    assert [o.name for o in scene.obstacles_for("blocked")] == ["wall", "post", "shelf"]


def test_the_catalogue_example_loads(tmp_path):
    from bt_meta.world.simulation.catalogue import load_catalogue

    (block,) = [b for b in yaml_blocks() if b.startswith("types:")]
    path = tmp_path / "my_objects.yaml"
    path.write_text(block)
    entry = load_catalogue(path)["block_long"]
    assert entry.primary == "bottom" and entry.role == "active" and set(entry.grasp_frames) == {"middle"}


def test_the_robot_example_loads(tmp_path):
    (block,) = [b for b in yaml_blocks() if b.startswith("name:")]
    path = tmp_path / "my_panda.yaml"
    path.write_text(block)
    robot = load_robot(path)
    assert robot.default_arm == "arm" and robot.scene_offset == (-0.33, 0.2, 0.2)
