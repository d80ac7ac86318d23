"""What an episode row records of its runs: the second exposure of every repaired run, a refinement kept or not.

The runs themselves are replaced here (``_one_run``): what is tested is the episode's bookkeeping, which the slow
campaign tests exercise with the real simulator."""

from __future__ import annotations

import pytest

from bt_meta.campaign import episode


def _report(attempts: int, saved: bool, status: str = "success") -> dict:
    return {"status": status, "achieved": status == "success", "truth": "", "failures": [],
            "attempts": [{"proposal": {"plugin": "p"}}] * attempts, "stop_reason": "", "simulated_seconds": 1.0,
            "refinement_saved": {"saved": saved, "method": "refined_m" if saved else None},
            "refinements_used": []}


@pytest.mark.parametrize("saved", [True, False])
def test_every_repaired_run_gets_a_second_exposure(tmp_path, monkeypatch, saved):
    memory = tmp_path / "memory.sqlite"
    memory.write_bytes(b"")
    runs = []

    def one_run(task, path, *, save):
        runs.append(save)
        # a repair that kept no refinement repeats its attempts on the second exposure
        return _report(2, saved) if save else _report(0 if saved else 2, saved)

    monkeypatch.setattr(episode, "_one_run", one_run)
    task = {"variant": "v", "configuration": "dual", "seed": 0, "expected": "repairable", "family": "magnetic",
            "memory": str(memory), "perfect_sensing": True}
    row = episode.run_episode(task)
    assert runs == [True, False]
    assert row["second_exposure"]["refinement_saved"] is saved
    assert row["second_exposure"]["attempts"] == (0 if saved else 2)


def test_a_run_without_attempts_or_that_failed_has_no_second_exposure(tmp_path, monkeypatch):
    memory = tmp_path / "memory.sqlite"
    memory.write_bytes(b"")
    for report in (_report(0, False), _report(2, False, status="failed")):
        monkeypatch.setattr(episode, "_one_run", lambda task, path, *, save, report=report: report)
        row = episode.run_episode({"variant": "v", "configuration": "dual", "seed": 0, "expected": "repairable",
                                   "family": "magnetic", "memory": str(memory), "perfect_sensing": True})
        assert row["second_exposure"] is None


def test_a_seeds_label_is_found_once_per_process_for_its_configurations(tmp_path, monkeypatch):
    """The configurations of one variant and seed share its label: labelled once, again when the scene file is
    edited, and every time with the model cache off; seed 0's is the manifest's (none labelled)."""
    from bt_meta.campaign import labeller

    made = []

    class Counting:
        def __init__(self, family, scene, start_seed, robot=None):
            made.append(start_seed)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return None

        def label(self, scene_path, variant):
            return labeller.Label("repairable", f"{scene_path} {variant} {made[-1]}")

    monkeypatch.setattr(labeller, "Labeller", Counting)
    scene = tmp_path / "variant.yaml"
    scene.write_text("objects: []\n", encoding="utf-8")
    task = {"family": "letters_A", "scene": str(scene), "seed": 1, "scene_variant": "v1"}
    first = episode.seed_label(task)
    assert [episode.seed_label({**task, "configuration": c}) for c in ("dual", "bt", "none")] == [first] * 3
    assert made == [1]
    assert episode.seed_label({**task, "seed": 2}).reason.endswith(" 2") and made == [1, 2]
    assert episode.seed_label({**task, "scene_variant": None}) is not first and len(made) == 3
    assert episode.seed_label({**task, "seed": 0}) is None and len(made) == 3
    scene.write_text("objects: []  # edited\n", encoding="utf-8")
    episode.seed_label(task)
    assert len(made) == 4
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    episode.seed_label(task)
    episode.seed_label(task)
    assert len(made) == 6
