"""``bt-meta bench campaign``: campaign throughput in episodes per core-hour, local pool against a Ray cluster.

One generated population, its demonstration memory recorded once (not timed), is run by ``bt-meta campaign run``
as a fresh process in each mode, in the same run: the local pool with 1 worker (the baseline: episodes in the
driver), the pool with 2 workers, and a Ray cluster of ``--nodes`` worker nodes of one CPU each behind a head that
runs nothing (``ray.cluster_utils.Cluster`` on this machine, started before and not timed, as an existing cluster
is; or ``--ray ADDRESS``). Each mode's figure is the wall time of the whole command; episodes per core-hour count
the cores it was given (workers, or the cluster's CPUs). Ratios are against the 1-worker pool of the same run, and
every mode must end every episode as the baseline did (status, attempts, failure kinds).

Offers:

* :func:`register` -- ``bt-meta bench campaign [--family F] [--n N] [--seed S] [--spec FILE] [--configuration C]
  [--nodes K] [--ray ADDRESS] [--rounds R] [--json]``
* :func:`run` -- the benchmark; returns the figures as a dict
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("campaign", help="campaign episodes per core-hour: pool (1, 2 workers) vs Ray")
    parser.add_argument("--family", default="letters_A", help="letters_A, letters_H, magnetic or housing")
    parser.add_argument("--n", type=int, default=8, help="generated variants (default 8)")
    parser.add_argument("--seed", type=int, default=1, help="generator seed (default 1)")
    parser.add_argument("--spec", help="perturbation spec (default: the family's)")
    parser.add_argument("--configuration", default="dual", help="plugin configuration (default dual)")
    parser.add_argument("--nodes", type=int, default=2, help="Ray worker nodes of one CPU each (default 2; 0: no Ray)")
    parser.add_argument("--ray", metavar="ADDRESS", help="an existing Ray cluster instead of the one started here")
    parser.add_argument("--rounds", type=int, default=1, help="times each mode runs, interleaved (default 1)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from bt_meta.campaign.families import family
    from bt_meta.configurations import CONFIGURATIONS

    family(args.family)
    if args.configuration not in CONFIGURATIONS:
        raise UserInputError(f"unknown configuration {args.configuration!r}; known: {', '.join(CONFIGURATIONS)}",
                             "<command line>")
    for name, value, low, high in (("--n", args.n, 1, 500), ("--nodes", args.nodes, 0, 16),
                                   ("--rounds", args.rounds, 1, 10)):
        if not low <= value <= high:
            raise UserInputError(f"{name} must be between {low} and {high}", "<command line>")
    if args.ray is not None:
        from bt_meta.campaign.runner import check_ray_address

        check_ray_address(args.ray)
    result = run(args.family, n=args.n, seed=args.seed, spec=args.spec, configuration=args.configuration,
                 nodes=args.nodes, ray_address=args.ray, rounds=args.rounds)
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0 if result["same_outcomes"] else 1


def _campaign_run(folder: Path, configuration: str, mode: list[str]) -> tuple[float, dict[str, Any]]:
    """Wall seconds of ``bt-meta campaign run`` as its own process, and its JSON."""
    started = time.perf_counter()
    # Started from the campaign folder: a ``bt_meta`` directory in the caller's cwd would shadow the installed one.
    done = subprocess.run([sys.executable, "-m", "bt_meta.cli", "campaign", "run", str(folder), "--configurations",
                           configuration, "--json", "--no-progress", *mode], cwd=folder, capture_output=True,
                          text=True, check=False)
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise BtMetaError("the timed campaign failed:\n" + "\n".join(done.stderr.strip().splitlines()[-12:]))
    return wall, json.loads(done.stdout)


def _outcomes(payload: dict[str, Any]) -> list[tuple[Any, ...]]:
    return sorted((e["variant"], e["configuration"], e["seed"], e["status"], e["attempts"], tuple(e["kinds"]))
                  for e in payload["episodes"])


def _cluster(nodes: int) -> Any:
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    for _ in range(nodes):
        cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    return cluster


def _cluster_cpus(address: str) -> int:
    import ray

    ray.init(address=address, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        return int(ray.cluster_resources().get("CPU", 0))
    finally:
        ray.shutdown()


def run(family_name: str = "letters_A", *, n: int = 8, seed: int = 1, spec: str | None = None,
        configuration: str = "dual", nodes: int = 2, ray_address: str | None = None, rounds: int = 1
        ) -> dict[str, Any]:
    from bt_meta.campaign.generator import generate
    from bt_meta.campaign.manifest import read_manifest
    from bt_meta.campaign.runner import ensure_memory

    modes: list[tuple[str, int, list[str]]] = [("pool, 1 worker", 1, ["--workers", "1"]),
                                               ("pool, 2 workers", 2, ["--workers", "2"])]
    cluster = None
    notes = []
    if ray_address is not None or nodes > 0:
        try:
            import ray  # noqa: F401
        except ImportError:
            notes.append("Ray left out: pip install 'bt-meta[ray]'")
        else:
            if ray_address is None:
                cluster = _cluster(nodes)
                address, cores, name = cluster.address, nodes, f"Ray, {nodes} node(s) x 1 CPU"
            else:
                address, name = ray_address, f"Ray at {ray_address}"
                cores = _cluster_cpus(address)
            modes.append((name, cores, ["--ray", address]))
    try:
        with tempfile.TemporaryDirectory(prefix="bt_meta_bench_campaign_") as root:
            base = Path(root) / "base"
            generate(family_name, n, seed, base, spec_path=spec)
            ensure_memory(base, read_manifest(base), echo=lambda text: None)
            walls: dict[str, list[float]] = {name: [] for name, _, _ in modes}
            loads: dict[str, list[float]] = {name: [] for name, _, _ in modes}
            outcomes: dict[str, list[list[tuple[Any, ...]]]] = {name: [] for name, _, _ in modes}
            episodes = 0
            for k in range(rounds):
                for index, (name, _, mode) in enumerate(modes):
                    folder = Path(root) / f"round{k}_mode{index}"
                    shutil.copytree(base, folder)
                    loads[name].append(os.getloadavg()[0])
                    wall, payload = _campaign_run(folder, configuration, mode)
                    loads[name].append(os.getloadavg()[0])
                    walls[name].append(wall)
                    outcomes[name].append(_outcomes(payload))
                    episodes = len(payload["episodes"])
                    shutil.rmtree(folder)
    finally:
        if cluster is not None:
            cluster.shutdown()
    baseline = None
    rows = []
    for name, cores, _ in modes:
        wall = statistics.median(walls[name])
        per_core_hour = episodes / (wall * cores) * 3600.0
        if baseline is None:
            baseline = (wall, per_core_hour)
        rows.append({"mode": name, "cores": cores, "episodes": episodes, "wall_seconds": wall,
                     "wall_seconds_runs": walls[name], "episodes_per_hour": episodes / wall * 3600.0,
                     "episodes_per_core_hour": per_core_hour, "per_core_vs_pool_1": per_core_hour / baseline[1],
                     "speed_up_vs_pool_1": baseline[0] / wall,
                     "load_average": [min(loads[name]), max(loads[name])],
                     "same_outcomes_as_pool_1": all(o == outcomes[modes[0][0]][0] for o in outcomes[name])})
    return {"family": family_name, "variants": n, "seed": seed, "configuration": configuration, "rounds": rounds,
            "cpu_count": os.cpu_count(), "modes": rows,
            "same_outcomes": all(r["same_outcomes_as_pool_1"] for r in rows), "notes": notes}


def _print(result: dict[str, Any]) -> None:
    print(f"bench campaign: {result['variants']} {result['family']} variants (seed {result['seed']}), "
          f"{result['configuration']}, {result['rounds']} round(s), median wall time of `bt-meta campaign run` per "
          f"mode; {result['cpu_count']} cores on this machine")
    print(f"{'mode':<26} {'cores':>5} {'episodes':>8} {'wall s':>8} {'episodes/h':>10} {'per core-hour':>13} "
          f"{'vs pool 1':>9} {'speed-up':>8}  load avg  outcomes")
    for r in result["modes"]:
        print(f"{r['mode']:<26} {r['cores']:>5} {r['episodes']:>8} {r['wall_seconds']:>8.1f} "
              f"{r['episodes_per_hour']:>10.0f} {r['episodes_per_core_hour']:>13.0f} {r['per_core_vs_pool_1']:>9.2f} "
              f"{r['speed_up_vs_pool_1']:>8.2f}  {r['load_average'][0]:.1f}-{r['load_average'][1]:.1f}  "
              f"{'same' if r['same_outcomes_as_pool_1'] else 'DIFFERENT'}")
    for note in result["notes"]:
        print(note)
