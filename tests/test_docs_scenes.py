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
    shipped = load_robot("panda")  # the example is the shipped Panda's description, offset included
    assert robot.default_arm == "arm" and robot.scene_offset == shipped.scene_offset == (-0.22, 0.2, 0.2)
    assert robot.arm("arm").joints == shipped.arm("arm").joints
    assert robot.arm("arm").end_effector == shipped.arm("arm").end_effector


def test_the_offsets_the_prose_gives_are_the_robot_files():
    text = DOC.read_text(encoding="utf-8")
    for name in ("baxter", "panda", "ur5"):
        offset = "[" + ", ".join(f"{v:g}" if v == 0 else f"{v:.2f}" for v in load_robot(name).scene_offset) + "]"
        assert offset in text, (name, offset)


def test_the_added_frames_example_is_the_ur5s():
    import yaml

    from bt_meta.resources import robots_dir

    (block,) = [b for b in yaml_blocks() if b.startswith("added_frames:")]
    shipped = yaml.safe_load((robots_dir() / "ur5.yaml").read_text(encoding="utf-8"))
    assert yaml.safe_load(block)["added_frames"] == shipped["added_frames"]
