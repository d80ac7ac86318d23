"""A worker serving many episodes reuses the parsed models, never the world: the same seeds give the same outcomes
with and without reuse (``BT_META_MODEL_CACHE=0``)."""

from __future__ import annotations

import pytest

from bt_meta import model_cache

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from bt_meta.campaign.generator import generate
    from bt_meta.campaign.manifest import read_manifest
    from bt_meta.campaign.runner import ensure_memory

    folder = tmp_path_factory.mktemp("reuse") / "C"
    generate("letters_A", 2, 7, folder)
    manifest = read_manifest(folder)
    ensure_memory(folder, manifest, echo=lambda text: None)
    return folder, manifest


def _outcome(row):
    assert row["status"] != "crashed", row["error"]
    return (row["variant"], row["seed"], row["status"], row["attempts"], row["kinds"], row["repairs"],
            row["achieved"], row["simulated_seconds"], row["second_exposure"])


def test_the_same_seeds_give_the_same_outcomes_with_and_without_reuse(campaign, monkeypatch):
    from bt_meta.campaign.episode import episode_task, run_episode

    folder, manifest = campaign
    tasks = [episode_task(folder, manifest, variant, "dual", seed, perfect_sensing=True)
             for variant, seed in zip(manifest["variants"], (0, 1), strict=True)]
    model_cache.clear()
    monkeypatch.setenv("BT_META_MODEL_CACHE", "1")
    reused = [_outcome(run_episode(task)) for task in tasks]
    again = _outcome(run_episode(tasks[0]))  # every model from the cache, after another variant's world
    assert model_cache._ENTRIES, "nothing was cached: the test would compare fresh against fresh"
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    model_cache.clear()
    fresh = [_outcome(run_episode(task)) for task in tasks]
    assert reused == fresh
    assert again == fresh[0]
