"""A spare that stands in for a missing part (a rebinding) is watched by the grid-map monitor as the part was:
before, the demonstrated part's maps kept its name, so once the spare was picked the monitor saw "nothing" where
the part should be and the run failed `unexpected_configuration` after a correct substitution (dual trailed
symbolic on every missing-part-with-a-spare variant of the per-class ablation). Real simulator, perceived world."""

from __future__ import annotations

from pathlib import Path

import pytest

from bt_meta.campaign.families import family

from .test_grounding_spares import SCENE, TASK_FILE

pytestmark = pytest.mark.slow


def test_a_rebinding_records_which_demonstrated_part_the_object_stands_in_for(tmp_path):
    from bt_meta.campaign.episode import variant_world

    scene = tmp_path / "spare_magnet.yaml"
    scene.write_text(SCENE)
    _, _, world = variant_world(TASK_FILE, "nominal", scene, "spare", seed=0)
    try:
        assert world.stand_ins == {}
        world.rebind_object("active_part", "other_magnet")
        assert world.stand_ins == {"active": "other_magnet"}
        world.rebind_object("active_part", "block")  # a second rebinding: still keyed by the demonstrated part
        assert world.stand_ins == {"active": "block"}
    finally:
        world.close()


def test_under_dual_a_missing_part_with_a_spare_is_repaired_and_its_second_run_needs_no_attempt(tmp_path):
    from bt_meta.campaign.episode import run_episode
    from bt_meta.campaign.runner import ensure_memory

    scene = tmp_path / "spare_magnet.yaml"
    scene.write_text(SCENE)
    chosen = family("magnetic")
    ensure_memory(tmp_path, {"family": "magnetic", "seed": 0}, echo=lambda text: None)
    row = run_episode({"folder": str(tmp_path), "family": "magnetic", "task_file": chosen.task_file,
                       "problem": chosen.problem, "variant": "spare", "scene": str(scene), "scene_variant": "spare",
                       "expected": "repairable", "configuration": "dual", "seed": 0,
                       "memory": str(Path(tmp_path) / "memory.sqlite"), "perfect_sensing": False})
    assert row["status"] == "success" and row["achieved"] is True, row["stop_reason"]
    assert row["kinds"] == ["unknown_entity"] and row["repairs"] == ["object_substitution"]
    assert row["second_exposure"]["status"] == "success" and row["second_exposure"]["attempts"] == 0
