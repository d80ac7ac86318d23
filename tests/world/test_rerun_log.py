"""``bt-meta run --record-rrd``: an episode as a Rerun recording, read back entity by entity."""

from __future__ import annotations

import builtins
import json

import pytest

from bt_meta.cli import main
from bt_meta.resources import trees_dir

MAGNETS = str(trees_dir() / "magnetic_attach.yaml")


def test_without_the_extra_the_option_is_a_clear_error(tmp_path, capsys, monkeypatch):
    real_import = builtins.__import__

    def no_rerun(name, *args, **kwargs):
        if name == "rerun" or name.startswith("rerun."):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_rerun)
    code = main(["run", MAGNETS, "--problem", "nominal", "--record-rrd", str(tmp_path / "x.rrd")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "--record-rrd needs rerun-sdk: pip install 'bt-meta[rerun]'" in err


@pytest.mark.slow
def test_the_recording_holds_joints_poses_images_and_statuses_per_tick(tmp_path, capsys):
    pytest.importorskip("rerun", reason="the optional extra rerun (rerun-sdk) is not installed")
    from rerun.chunk import RrdReader

    path = tmp_path / "episode.rrd"
    code = main(["run", MAGNETS, "--problem", "nominal", "--record-rrd", str(path), "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0 and result["status"] == "SUCCESS" and result["rrd"] == str(path)
    rows: dict[str, int] = {}
    texts: list[str] = []
    for chunk in RrdReader(path).stream().to_chunks():
        entity = str(chunk.entity_path)
        rows[entity] = rows.get(entity, 0) + chunk.num_rows
        if entity == "/tree/status":
            batch = chunk.to_record_batch()
            column = next(name for name in batch.schema.names if name.endswith("TextLog:text"))
            texts += [str(v[0]) for v in batch.column(column).to_pylist()]
    ticks = result["ticks"]
    assert rows["/robot/joints/right_s0"] == ticks and rows["/robot/gripper/right"] == ticks
    assert rows["/objects/active"] == ticks and rows["/objects/reference"] == ticks
    assert rows["/objects/active/box"] == 1  # static
    assert 2 <= rows["/camera/top"] <= ticks // 10 + 2
    assert len(texts) == ticks and texts[-1].startswith("SUCCESS") and texts[0].startswith("RUNNING")
    assert any("MoveTo(joint)=SUCCESS" in text for text in texts)
