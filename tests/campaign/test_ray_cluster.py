"""Campaigns on a real multi-node Ray cluster on this machine: a head and two worker nodes (``ray.cluster_utils``),
the driver a ``bt-meta campaign run --ray ADDRESS`` process of its own, as against any existing cluster."""

from __future__ import annotations

import json
import shutil
import sqlite3
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.slow
pytest.importorskip("ray.exceptions")  # Ray itself, not a stray folder named ray (Ray's /tmp/ray) on sys.path
import ray  # noqa: E402

SPEC = """family: housing
perturbations:
  - shift: {probability: 1.0, objects: [housing], distance: [0.005, 0.01]}
  - remove: {probability: 0.3, objects: [housing], spare_probability: 0.0}
"""
"""Episodes of a second or two: the housing nudged by millimetres (succeeds), or gone (fails at once)."""


@pytest.fixture(scope="module")
def population(tmp_path_factory):
    """Eight housing variants of two outcomes, memory recorded, and what the local pool (one worker) makes of them."""
    from bt_meta.campaign.generator import generate
    from bt_meta.campaign.manifest import read_manifest
    from bt_meta.campaign.runner import ensure_memory, run_campaign

    root = tmp_path_factory.mktemp("ray_population")
    (root / "spec.yaml").write_text(SPEC, encoding="utf-8")
    folder = root / "C"
    generate("housing", 8, 3, folder, spec_path=root / "spec.yaml")
    ensure_memory(folder, read_manifest(folder), echo=lambda text: None)
    pool = root / "pool"
    shutil.copytree(folder, pool)
    result = run_campaign(pool, configurations=("retry",), workers=1, progress=False, echo=lambda text: None)
    outcomes = _outcomes(result["episodes"])
    assert len(outcomes) == 8 and len({o[1] for o in outcomes.values()}) == 2  # both outcomes are there
    return folder, outcomes


@pytest.fixture(scope="module")
def cluster():
    """A head that runs nothing (0 CPUs) and two worker nodes of one CPU each."""
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    workers = [cluster.add_node(num_cpus=1) for _ in range(2)]
    cluster.wait_for_nodes()
    yield cluster, workers
    cluster.shutdown()


def _outcomes(episodes):
    return {(e["variant"], e["configuration"], int(e["seed"])): (e["status"], e["attempts"], tuple(e["kinds"]))
            for e in episodes}


def _run(folder, address):
    return [sys.executable, "-m", "bt_meta.cli", "campaign", "run", str(folder), "--configurations", "retry",
            "--ray", address, "--json", "--no-progress"]


def _keys(folder):
    with sqlite3.connect(folder / "campaign.sqlite") as connection:
        return connection.execute("SELECT variant, configuration, seed FROM episodes").fetchall()


def _busy(node) -> bool:
    """Whether the node's one CPU is taken (an episode leased there), as its raylet last reported to the head: a
    resource fully in use is left out of the node's available resources."""
    from ray._private.state import available_resources_per_node

    available = available_resources_per_node().get(node.node_id)
    return available is not None and available.get("CPU", 0.0) < 1.0


def test_a_two_node_cluster_gives_the_local_pool_s_outcomes(population, cluster, tmp_path):
    source, pool = population
    folder = tmp_path / "C"
    shutil.copytree(source, folder)
    result = subprocess.run(_run(folder, cluster[0].address), capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert _outcomes(json.loads(result.stdout)["episodes"]) == pool
    keys = _keys(folder)
    assert len(keys) == len(set(keys)) == 8
    assert all((folder / "episodes" / f"{v}__{c}__{s}.json").is_file() for v, c, s in keys)


def _lose_a_node_mid_campaign(folder, head, doomed):
    """Run the campaign in ``folder`` and kill ``doomed`` once it holds an episode and one episode is stored:
    (return code, stdout, stderr, episodes stored before the kill)."""
    process = subprocess.Popen(_run(folder, head.address), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    ray.init(address=head.address, include_dashboard=False, log_to_driver=False)
    try:
        while time.monotonic() < deadline and process.poll() is None:
            try:
                if (folder / "campaign.sqlite").exists() and len(_keys(folder)) >= 1 and _busy(doomed):
                    break
            except sqlite3.OperationalError:  # the file is there, its table not yet
                pass
            time.sleep(0.05)
        assert process.poll() is None, "the campaign ended before a node could be lost"
        before = len(_keys(folder))
        head.remove_node(doomed, allow_graceful=False)  # killed, as a node that crashes or loses power
        stdout, stderr = process.communicate(timeout=240)
    finally:
        ray.shutdown()
        if process.poll() is None:
            process.kill()
    return process.returncode, stdout, stderr, before


def test_a_worker_node_lost_mid_campaign_loses_no_episode_and_counts_none_twice(population, cluster, tmp_path):
    """The node is removed while both nodes run episodes and more wait: the driver sees the episode that died with it,
    submits it again to the node left, and every episode key ends in the database once, with the pool's outcome.

    The head's view of a node's CPU lags by its report period, so the episode it held may have ended just before
    the kill (a node lost between two episodes, which loses nothing and tests nothing): every attempt must end
    with the pool's outcomes, and the scenario is run again on a fresh node until a loss is seen (3 attempts)."""
    source, pool = population
    head, doomed = cluster[0], cluster[1][1]
    seen_a_loss = []
    for attempt in range(3):
        folder = tmp_path / f"C{attempt}"
        shutil.copytree(source, folder)
        code, stdout, stderr, before = _lose_a_node_mid_campaign(folder, head, doomed)
        assert code == 0, stderr[-3000:]
        assert before < 8
        keys = _keys(folder)
        assert len(keys) == len(set(keys)) == 8
        assert _outcomes(json.loads(stdout)["episodes"]) == pool
        seen_a_loss.append("lost on the cluster" in stderr)
        if seen_a_loss[-1]:
            assert "submitted again" in stderr, stderr[-3000:]
            break
        doomed = head.add_node(num_cpus=1)  # the next attempt loses this one
        head.wait_for_nodes()
    assert any(seen_a_loss), f"no attempt lost a node while it held an episode: {seen_a_loss}"


def test_an_unreachable_head_is_an_error_naming_its_address_quickly(population, tmp_path):
    import socket

    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    folder = tmp_path / "C"
    shutil.copytree(population[0], folder)
    started = time.monotonic()
    result = subprocess.run(_run(folder, f"127.0.0.1:{port}"), capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert f"--ray '127.0.0.1:{port}': no Ray cluster answers there" in result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    assert time.monotonic() - started < 20


def test_a_listener_that_is_no_ray_head_is_refused_within_the_connect_bound():
    """Something listens but never answers gRPC's preface: ``ray.init`` would wait minutes; the check gives up."""
    import socket

    from bt_meta.campaign.runner import RayAddressError, check_ray_address

    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(1)
        address = f"127.0.0.1:{silent.getsockname()[1]}"
        started = time.monotonic()
        with pytest.raises(RayAddressError, match=rf"--ray '{address}': no Ray cluster answers there \(no answer"):
            check_ray_address(address, timeout=1.0)
        assert time.monotonic() - started < 5
