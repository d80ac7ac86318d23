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
