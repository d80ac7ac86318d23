"""Static obstacles in scene files: parsed with located errors, built as static bodies the cameras see, mirrored
into the collision checker, and a variant with one in the way is classified ``collision``."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bt_meta.cli import main
from bt_meta.errors import ConfigError
from bt_meta.resources import trees_dir
from bt_meta.world.simulation.obstacles import ObstacleError, obstacle_model
from bt_meta.world.simulation.scenes import load_scene

SCENE = """\
scene: with_obstacles
objects:
  - {name: b0, type: megablok_1x1, colour: red, pose: [0.6, -0.3, table, 0, 0, 0]}
obstacles:
  - {name: post, shape: post, radius: 0.02, height: 0.3, pose: [0.6, -0.1, table, 0, 0, 0]}
  - {name: wall, shape: wall, size: [0.4, 0.02, 0.2], colour: dark_grey, pose: [0.9, -0.2, table, 0, 0, 90]}
variants:
  boxed:
    obstacles:
      - {name: box, shape: box, size: [0.1, 0.1, 0.1], pose: [0.7, -0.3, table, 0, 0, 0]}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def test_obstacle_models_stand_on_their_origin():
    shelf = obstacle_model("shelf", {"size": [0.2, 0.3, 0.1], "thickness": 0.01})
    low, high = shelf.extent()
    assert low == pytest.approx([-0.1, -0.15, 0.0]) and high == pytest.approx([0.1, 0.15, 0.1])
    assert shelf.mass == 0.0 and len(shelf.parts) == 3
    with pytest.raises(ObstacleError, match="unknown obstacle shape 'cone'; known: box, wall, post, shelf"):
        obstacle_model("cone", {})
    with pytest.raises(ObstacleError, match="radius must be a positive number"):
        obstacle_model("post", {"radius": -1, "height": 0.2})


def test_scene_obstacles_and_variant_obstacles(tmp_path):
    scene = load_scene(write(tmp_path, SCENE))
    assert [o.name for o in scene.obstacles_for()] == ["post", "wall"]
    assert [o.name for o in scene.obstacles_for("boxed")] == ["post", "wall", "box"]
    assert [o.name for o in scene.objects_for("boxed")] == ["b0"]
    wall = scene.obstacles[1]
    assert wall.shape == "wall" and wall.model.colour == "dark_grey" and wall.position[2] is None


@pytest.mark.parametrize(
    ("old", "new", "needle", "message"),
    [
        ("shape: post", "shape: cone", "cone", "obstacle 'post': unknown shape 'cone'; known: box, wall, post, "
                                                      "shelf"),
        ("radius: 0.02, ", "", "{name: post", "obstacle 'post': radius must be a positive number (metres), got None"),
        ("size: [0.4, 0.02, 0.2]", "size: [0.4, 0.2]", "{name: wall",
         "obstacle 'wall': size must be [x, y, z] (metres), got [0.4, 0.2]"),
        ("radius: 0.02", "size: [1, 1, 1]", "size: [1", "obstacle 'post': a post takes height, radius, not size"),
        ("name: box", "name: b0", "{name: b0, shape", "duplicate object name 'b0' (first at line 3)"),
    ],
)
def test_bad_obstacles_fail_at_their_line(tmp_path, old, new, needle, message):
    assert old in SCENE
    path = write(tmp_path, SCENE.replace(old, new, 1))
    line, text = next((n, t) for n, t in enumerate(path.read_text().splitlines(), 1) if needle in t)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert str(info.value) == f"{path}:{line}:{text.index(needle) + 1}: {message}"


@pytest.mark.slow
def test_obstacles_are_static_bodies_cameras_and_collision_checks_see(tmp_path):
    from bt_meta.world.simulation.camera import TopViewCamera
    from bt_meta.world.simulation.sim import Simulation

    scene = load_scene(write(tmp_path, SCENE))
    with Simulation() as sim:
        scene.build(sim, "boxed")
        assert sim.object_names() == ("b0",)  # obstacles are not task objects
        obstacles = sim.obstacles()
        assert set(obstacles) == {"post", "wall", "box"}
        _, pose = obstacles["post"]
        assert pose[:3, 3] == pytest.approx([0.6, -0.1, sim.table.top_z], abs=1e-9)  # static: did not fall
        image = TopViewCamera(sim, centre=(0.7, -0.2)).capture()
        assert image.segmentation is not None
        seen = {sim.obstacle_name_of(int(i)) for i in np.unique(image.segmentation & 0xFFFFFF)}
        assert seen >= {"post", "wall", "box"}


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["baxter", "panda", "ur5"])
def test_a_variant_with_an_obstacle_in_the_way_is_a_collision(capsys, robot):
    code = main(["run", str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal",
                 "--variant", "shelf_over_reference", "--robot", robot, "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 1 and result["status"] == "FAILURE"
    (failure,) = result["failures"]
    assert failure["kind"] == "collision" and failure["action"] == "MoveTo"
    assert "shelf" in failure["evidence"]["objects"]
