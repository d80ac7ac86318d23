"""A user's kitting task (issue 31, tests/data/usertask_kit): parts of several types -- a pin of the scene's own
catalogue, a 1x1 and a 1x2 block -- put into slots on a tray, an obstacle of the nominal scene. A campaign's
variant files keep the scene's catalogue and obstacles, and the labeller does not judge the kit by the Mega Blok
letters' inventory rule (every variant was ``unrepairable``: the pin is no block)."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from bt_meta.campaign.generator import VARIANT_NAME, placed_objects, scene_text
from bt_meta.world.simulation.scenes import load_scene

DATA = Path(__file__).resolve().parent.parent / "data" / "usertask_kit"


def test_a_variant_file_keeps_the_scene_catalogue_and_obstacles(tmp_path: Path):
    scene = load_scene(str(DATA / "scene.yaml"))
    objects = placed_objects(scene)
    objects[0] = replace(objects[0], x=objects[0].x + 0.02)
    path = tmp_path / "elsewhere" / "v.yaml"  # read from another folder than the scene's, as variants/ is
    path.parent.mkdir()
    path.write_text(scene_text(scene, "v", objects, [{"kind": "shift", "object": objects[0].name}]))
    variant = load_scene(str(path))
    assert {o.name: o.type for o in variant.objects_for(VARIANT_NAME)}["pin"] == "pin"
    assert [o.name for o in variant.obstacles_for(VARIANT_NAME)] == ["tray"]
    assert variant.obstacles[0].model.extent()[1][2] == pytest.approx(0.01, abs=1e-6)


@pytest.mark.slow
def test_a_kit_of_other_parts_is_not_judged_by_the_letters_inventory(tmp_path: Path):
    from bt_meta.campaign.families import task_family
    from bt_meta.campaign.labeller import Labeller

    shutil.copytree(DATA, tmp_path / "kit")
    scene = load_scene(str(tmp_path / "kit" / "scene.yaml"))
    with Labeller(task_family(tmp_path / "kit" / "kit.yaml", "nominal"), scene, start_seed=None) as labeller:
        label = labeller.label(scene.path, None)
    assert label.expected == "nominal_equivalent", label.reason
