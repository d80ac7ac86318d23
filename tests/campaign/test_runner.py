"""The campaign runner end to end: JSON schema, resume after a real SIGKILL, the same outcomes on Ray."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """Two generated letters_A variants with the demonstration memory already recorded."""
    from bt_meta.campaign.generator import generate
    from bt_meta.campaign.manifest import read_manifest
    from bt_meta.campaign.runner import ensure_memory

    folder = tmp_path_factory.mktemp("campaign") / "C"
    generate("letters_A", 2, 7, folder)
    ensure_memory(folder, read_manifest(folder), echo=lambda text: None)
    return folder


def _cli(*args):
    return [sys.executable, "-m", "bt_meta.cli", "campaign", *args]


def _rows(folder):
    with sqlite3.connect(folder / "campaign.sqlite") as connection:
        return connection.execute("SELECT variant, configuration, seed, seconds FROM episodes").fetchall()


def test_sigkill_then_resume_loses_nothing_and_counts_nothing_twice(campaign, tmp_path):
    folder = tmp_path / "C"
    shutil.copytree(campaign, folder)
    args = _cli("run", str(folder), "--configurations", "retry", "--seeds", "2", "--workers", "1", "--no-progress")
    process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and process.poll() is None:
        try:
            if (folder / "campaign.sqlite").exists() and len(_rows(folder)) >= 1:
                break
        except sqlite3.OperationalError:  # the file is there, its table not yet
            pass
        time.sleep(0.2)
    assert process.poll() is None, "the run ended before it could be killed"
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    before = _rows(folder)
    assert 1 <= len(before) < 4
    result = subprocess.run([*args[:-1], "--json", "--no-progress"], capture_output=True, text=True, check=True)
    payload = json.loads(result.stdout)
    after = _rows(folder)
    keys = [(v, c, s) for v, c, s, _ in after]
    assert len(keys) == len(set(keys)) == 4
    assert set(before) <= set(after)  # the episodes finished before the kill were not run again
    assert len(payload["episodes"]) == 4 and payload["summary"]["episodes"] == 4
    episode = payload["episodes"][0]
    for key in ("variant", "configuration", "seed", "expected", "status", "attempts", "kinds"):
        assert key in episode
    assert f"{len(before)} already done" in result.stderr
    for row in payload["episodes"]:
        assert (folder / row["run_report"]).is_file()
    report = subprocess.run(_cli("report", str(folder), "-o", str(folder / "report.html"), "--json"),
                            capture_output=True, text=True, check=True)
    summary = json.loads(report.stdout)
    assert summary["episodes"] == 4 and summary["table"][0]["wilson95"][0] <= summary["table"][0]["rate"]
    text = (folder / "report.html").read_text()
    assert "Wilson 95 %" in text and "Confusion" in text and "<svg" in text


def test_a_two_worker_pool_finishes_cleanly_with_json(campaign, tmp_path):
    """The local pool's shutdown terminates what is in flight; once every episode is done that is nothing, and the
    command exits 0 with its JSON (it raised after the last episode when the pool had dropped its process table)."""
    folder = tmp_path / "C"
    shutil.copytree(campaign, folder)
    result = subprocess.run(_cli("run", str(folder), "--configurations", "retry", "--workers", "2", "--json",
                                 "--no-progress"), capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    payload = json.loads(result.stdout)
    assert len(payload["episodes"]) == 2 and len(_rows(folder)) == 2


def test_episodes_of_a_second_seed_are_judged_by_the_label_of_their_own_start_noise(campaign, tmp_path):
    """``--seeds 2``: the manifest's labels are seed 0's; each seed-1 episode labels its variant again and keeps the
    manifest's as ``expected_as_generated``."""
    from bt_meta.campaign.episode import episode_task, seed_label
    from bt_meta.campaign.manifest import read_manifest

    folder = tmp_path / "C"
    shutil.copytree(campaign, folder)
    result = subprocess.run(_cli("run", str(folder), "--configurations", "retry", "--seeds", "2", "--workers", "1",
                                 "--no-progress"), capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    manifest = read_manifest(folder)
    variants = {v["name"]: v for v in manifest["variants"]}
    with sqlite3.connect(folder / "campaign.sqlite") as connection:
        rows = [json.loads(text) for (text,) in connection.execute("SELECT result FROM episodes")]
    assert sorted((r["variant"], r["seed"]) for r in rows) == sorted((v, s) for v in variants for s in (0, 1))
    for row in rows:
        generated = variants[row["variant"]]["expected"]
        if row["seed"] == 0:
            assert row["expected"] == generated and "expected_as_generated" not in row
        else:
            own = seed_label(episode_task(folder, manifest, variants[row["variant"]], "retry", 1))
            assert row["expected_as_generated"] == generated and row["expected"] == own.expected


def test_ray_gives_the_same_outcomes_as_the_pool(campaign, tmp_path):
    pytest.importorskip("ray.exceptions")  # Ray itself, not a stray folder named ray (Ray's /tmp/ray) on sys.path
    from bt_meta.campaign.runner import run_campaign

    outcomes = {}
    for name, options in (("pool", {"workers": 1}), ("ray", {"ray_address": "auto", "workers": 2})):
        folder = tmp_path / name
        shutil.copytree(campaign, folder)
        result = run_campaign(folder, configurations=("dual",), seeds=1, progress=False, echo=lambda t: None,
                              **options)
        outcomes[name] = sorted((e["variant"], e["status"], e["attempts"], tuple(e["kinds"]))
                                for e in result["episodes"])
    assert outcomes["pool"] == outcomes["ray"]
    assert len(outcomes["pool"]) == 2
