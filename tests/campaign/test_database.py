"""The campaign directory and database: no episode twice; other versions, manifests, half-written dirs refused."""

from __future__ import annotations

import json

import pytest

from bt_meta.campaign import CAMPAIGN_VERSION
from bt_meta.campaign.database import CampaignDatabase
from bt_meta.campaign.manifest import CampaignDirError, manifest_digest, read_manifest, write_manifest
from bt_meta.cli import main


def _manifest(folder, version=CAMPAIGN_VERSION):
    (folder / "variants").mkdir(parents=True, exist_ok=True)
    (folder / "variants" / "v.yaml").write_text("scene: v\n", encoding="utf-8")
    write_manifest(folder, {"campaign_version": version, "family": "letters_A", "task_file": "letters.yaml",
                            "problem": "A", "seed": 0, "spec_file": "x", "spec": {},
                            "variants": [{"name": "v", "file": "variants/v.yaml", "expected": "repairable"}]})


def _row(**changes):
    row = {"variant": "v", "configuration": "dual", "seed": 0, "expected": "repairable", "status": "success",
           "success": True, "attempts": 1, "seconds": 1.5}
    row.update(changes)
    return row


def test_an_episode_is_stored_once(tmp_path):
    _manifest(tmp_path)
    with CampaignDatabase.open(tmp_path, manifest_digest(tmp_path)) as db:
        assert db.add(_row())
        assert not db.add(_row(status="failed"))
        assert db.add(_row(seed=1))
        assert db.done() == {("v", "dual", 0), ("v", "dual", 1)}
        assert [r["status"] for r in db.rows()] == ["success", "success"]


def test_another_manifest_or_version_is_refused(tmp_path):
    _manifest(tmp_path)
    CampaignDatabase.open(tmp_path, manifest_digest(tmp_path)).close()
    with pytest.raises(CampaignDirError, match=r"another campaign\.json"):
        CampaignDatabase.open(tmp_path, "0" * 64)
    import sqlite3

    with sqlite3.connect(tmp_path / "campaign.sqlite") as connection:
        connection.execute("UPDATE meta SET value = '0' WHERE key = 'campaign_version'")
    with pytest.raises(CampaignDirError, match="another version"):
        CampaignDatabase.open(tmp_path, manifest_digest(tmp_path))


def test_half_written_and_other_version_directories_are_refused(tmp_path, capsys):
    half = tmp_path / "half"
    (half / "variants").mkdir(parents=True)
    with pytest.raises(CampaignDirError, match="half-written"):
        read_manifest(half)
    old = tmp_path / "old"
    _manifest(old, version=0)
    assert main(["campaign", "run", str(old), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{old / 'campaign.json'}: made by another version" in err and "Traceback" not in err
    assert main(["campaign", "report", str(half)]) == 2
    assert "half-written" in capsys.readouterr().err
    broken = tmp_path / "broken"
    _manifest(broken)
    (broken / "variants" / "v.yaml").unlink()
    with pytest.raises(CampaignDirError, match="missing"):
        read_manifest(broken)
    text = json.loads((broken / "campaign.json").read_text())
    assert text["campaign_version"] == CAMPAIGN_VERSION


def test_a_ray_address_that_does_not_answer_is_named(tmp_path, capsys):
    _manifest(tmp_path)
    assert main(["campaign", "run", str(tmp_path), "--ray", "127.0.0.1:9", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--ray '127.0.0.1:9': no Ray cluster answers there" in err and "Traceback" not in err


def test_unknown_configuration_exits_2(tmp_path, capsys):
    _manifest(tmp_path)
    assert main(["campaign", "run", str(tmp_path), "--configurations", "dual,bogus"]) == 2
    assert "unknown bogus" in capsys.readouterr().err


def test_perfect_and_perceived_sensing_are_never_mixed(tmp_path):
    _manifest(tmp_path)
    with CampaignDatabase.open(tmp_path, manifest_digest(tmp_path)) as db:
        db.check_sensing("perceived")
        db.check_sensing("perceived")
        with pytest.raises(CampaignDirError, match="ran with perceived sensing, this run asks for perfect"):
            db.check_sensing("perfect")


def test_the_local_pool_streams_every_result_and_leaves_no_worker_behind():
    import multiprocessing

    from bt_meta.campaign.runner import _pool_results

    tasks = [{"k": k} for k in range(5)]
    results = list(_pool_results(tasks, 2, json.dumps))
    assert sorted(results) == sorted(json.dumps(t) for t in tasks)
    stopped = _pool_results(tasks, 2, json.dumps)
    next(stopped)
    stopped.close()  # the driver stops early (an interrupt): the workers are terminated
    import time

    deadline = time.monotonic() + 10
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert multiprocessing.active_children() == []
