"""``bt-meta bench episode``: how fast a whole campaign episode runs against simulated time, next to raw pybullet.

An episode here is what a campaign runs: plan and run the problem with monitors and the meta-reasoner under a
configuration, in a fresh world built from the scene, on a copy of a demonstration memory recorded once beforehand
(not timed). Two ways of running it are timed in the same run, each named for what it counts:

* **fresh process** (``real_time_factor``, the issue's figure): a new Python process pinned to one core imports
  bt-meta, loads the robot models, builds the world, plans and runs one episode; simulated seconds / wall seconds
  of the whole process, interpreter start and model loading included. ``inner_real_time_factor`` counts only the
  run itself (plan + ticks).
* **worker, steady state** (``worker_real_time_factor``): one process pinned to one core serves ``repeat + 1``
  episodes in a row, as a campaign's pool worker or Ray worker does; the first (imports, first model loads) is
  left out, the others are timed from the start of their world to the end of their run: what each further
  episode costs a worker that reuses the immutable models (:mod:`bt_meta.model_cache`) with a fresh world.

The baseline is pybullet's raw stepping rate with the same robot and scene (simulated seconds / seconds of
``stepSimulation`` alone), measured inside each timed child on its core right after each timed episode (left out
of that episode's and process's figures): on a shared machine the load changes from minute to minute, and a ratio
is only fair against a baseline measured under the same load. ``ratio_to_pybullet`` and
``worker_ratio_to_pybullet`` are medians of these paired ratios; ``pybullet_real_time_factor`` is the median raw
rate. The ``cpu_*`` figures are the same ratios in CPU seconds of the process (what a loaded machine changes
least). Each child also reports where its wall time went (``phases``).

Offers:

* :func:`register` -- ``bt-meta bench episode [--family F] [--configuration C] [--repeat N] [--json]``
* :func:`run` -- the benchmark; returns the figures as a dict
* :func:`child` -- the timed episodes of one process (``python -m bt_meta.bench.episode TASKS.json``)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["child", "register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("episode", help="a whole campaign episode's real-time factor vs raw pybullet")
    parser.add_argument("--family", default="letters_A", help="letters_A, letters_H, magnetic or housing")
    parser.add_argument("--configuration", default="dual", help="plugin configuration (default dual)")
    parser.add_argument("--repeat", type=int, default=3, help="episodes (processes) to time (default 3)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from bt_meta.campaign.families import family
    from bt_meta.configurations import CONFIGURATIONS

    family(args.family)
    if args.configuration not in CONFIGURATIONS:
        raise UserInputError(f"unknown configuration {args.configuration!r}; known: {', '.join(CONFIGURATIONS)}",
                             "<command line>")
    if not 1 <= args.repeat <= 50:
        raise UserInputError("--repeat must be between 1 and 50", "<command line>")
    result = run(args.family, args.configuration, repeat=args.repeat)
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0


def _pybullet_rate(scene: str, steps: int = 2400) -> dict[str, float]:
    """Raw ``stepSimulation`` with the robot and the scene's objects: steps per second and real-time factor."""
    import pybullet

    from bt_meta.world.simulation.scenes import load_scene
    from bt_meta.world.simulation.sim import Simulation
    from bt_meta.world.simulation.sim_world import quiet_stdout

    with quiet_stdout():
        sim = Simulation(seed=0, visuals="light")
    try:
        load_scene(scene).build(sim, None, seed=0)
        started, cpu = time.perf_counter(), time.process_time()
        for _ in range(steps):
            pybullet.stepSimulation(physicsClientId=sim.client)
        wall, cpu = time.perf_counter() - started, time.process_time() - cpu
        return {"steps": steps, "steps_per_second": steps / wall,
                "real_time_factor": steps * sim.time_step / wall,
                "cpu_real_time_factor": steps * sim.time_step / max(cpu, 1e-9)}
    finally:
        sim.close()


def _timed_process(tasks: list[dict[str, Any]], task_file: Path) -> tuple[float, list[dict[str, Any]]]:
    """Wall seconds of a child process serving ``tasks`` in a row, and what it reports per episode."""
    task_file.write_text(json.dumps(tasks), encoding="utf-8")
    started = time.perf_counter()
    # Run from the task's folder: ``-m`` puts the working directory first on sys.path, and a checkout of another
    # bt-meta there (run from a different worktree) would be imported instead of this one.
    done = subprocess.run([sys.executable, "-m", "bt_meta.bench.episode", str(task_file)], cwd=task_file.parent,
                          capture_output=True, text=True, check=False)
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise BtMetaError("the timed episode failed:\n" + "\n".join(done.stderr.strip().splitlines()[-12:]))
    return wall, json.loads(done.stdout.strip().splitlines()[-1])


def run(family_name: str = "letters_A", configuration: str = "dual", *, repeat: int = 3) -> dict[str, Any]:
    from bt_meta.campaign.families import family
    from bt_meta.campaign.runner import ensure_memory
    from bt_meta.world.simulation.scenes import load_scene
    from bt_meta.world.simulation.sim_world import quiet_stdout

    with quiet_stdout():
        import pybullet  # noqa: F401  (prints its build time on import)
    chosen = family(family_name)
    scene_path = str(load_scene(chosen.scene).path)
    with tempfile.TemporaryDirectory(prefix="bt_meta_bench_episode_") as folder:
        ensure_memory(Path(folder), {"family": family_name, "seed": 0}, echo=lambda text: None)

        def task(seed: int) -> dict[str, Any]:
            return {"folder": folder, "family": family_name, "task_file": chosen.task_file,
                    "problem": chosen.problem, "variant": "nominal", "scene": scene_path, "scene_variant": None,
                    "expected": "nominal_equivalent", "configuration": configuration, "seed": seed,
                    "memory": str(Path(folder) / "memory.sqlite"), "perfect_sensing": True}

        runs = []
        for k in range(repeat):
            wall, (inner,) = _timed_process([task(k)], Path(folder) / f"task{k}.json")
            # the process's own figures leave out the raw stepping it did after its episode
            inner["process_wall_seconds"] = wall - inner["raw"]["total_wall_seconds"]
            inner["real_time_factor"] = inner["simulated_seconds"] / inner["process_wall_seconds"]
            inner["ratio_to_pybullet"] = inner["real_time_factor"] / inner["raw"]["real_time_factor"]
            inner["cpu_ratio_to_pybullet"] = (inner["simulated_seconds"] / inner["process_cpu_seconds"]
                                              / inner["raw"]["cpu_real_time_factor"])
            runs.append(inner)
        # The worker: a warm-up episode (seed 0), then the same seeds as the fresh processes.
        worker_wall, served = _timed_process([task(0)] + [task(k) for k in range(repeat)],
                                             Path(folder) / "worker.json")
    factor = statistics.median(r["real_time_factor"] for r in runs)
    inner_factor = statistics.median(r["inner_real_time_factor"] for r in runs)
    phases = {name: statistics.median(r["phases"][name] for r in runs) for name in runs[0]["phases"]}
    steady = served[1:]
    for r in steady:
        r["ratio_to_pybullet"] = r["simulated_seconds"] / r["phases"]["episode"] / r["raw"]["real_time_factor"]
        r["cpu_ratio_to_pybullet"] = (r["simulated_seconds"] / r["episode_cpu_seconds"]
                                      / r["raw"]["cpu_real_time_factor"])
    raws = [r["raw"] for r in runs + steady]
    worker_simulated = sum(r["simulated_seconds"] for r in steady)
    worker_seconds = sum(r["phases"]["episode"] for r in steady)
    worker_phases = {name: statistics.median(r["phases"][name] for r in steady)
                     for name in ("episode", "world_and_plugins", "run")}
    same = [(r["status"], r["attempts"], r["kinds"]) for r in runs] == [
        (r["status"], r["attempts"], r["kinds"]) for r in steady]
    return {"family": family_name, "configuration": configuration, "repeat": repeat,
            "real_time_factor": factor, "inner_real_time_factor": inner_factor,
            "worker_real_time_factor": worker_simulated / worker_seconds if worker_seconds > 0 else 0.0,
            "pybullet_real_time_factor": statistics.median(r["real_time_factor"] for r in raws),
            "pybullet_steps_per_second": statistics.median(r["steps_per_second"] for r in raws),
            "ratio_to_pybullet": statistics.median(r["ratio_to_pybullet"] for r in runs),
            "worker_ratio_to_pybullet": statistics.median(r["ratio_to_pybullet"] for r in steady),
            "cpu_ratio_to_pybullet": statistics.median(r["cpu_ratio_to_pybullet"] for r in runs),
            "worker_cpu_ratio_to_pybullet": statistics.median(r["cpu_ratio_to_pybullet"] for r in steady),
            "simulated_seconds": statistics.median(r["simulated_seconds"] for r in runs),
            "process_wall_seconds": statistics.median(r["process_wall_seconds"] for r in runs),
            "phases": phases, "worker": {"episodes": len(steady), "simulated_seconds": worker_simulated,
                                         "episode_seconds": worker_seconds, "process_wall_seconds": worker_wall,
                                         "phases": worker_phases, "same_outcomes_as_fresh": same,
                                         "warm_up": served[0]},
            "runs": runs, "worker_runs": steady}


def child(task_path: str) -> list[dict[str, Any]]:
    """The timed episodes of one process, in a row: phases (s), simulated time and outcome of each."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    started = time.perf_counter()
    from bt_meta.world.simulation.sim_world import quiet_stdout

    with quiet_stdout():
        import pybullet  # noqa: F401

        from bt_meta import configurations  # noqa: F401
        from bt_meta.campaign import episode  # noqa: F401
        from bt_meta.meta import MetaExecutor  # noqa: F401
    imported = time.perf_counter() - started
    tasks = json.loads(Path(task_path).read_text(encoding="utf-8"))
    from bt_meta.campaign.episode import run_episode

    out = []
    for task in tasks:
        phases: dict[str, float] = {"import": imported} if not out else {}
        mark, cpu = time.perf_counter(), time.process_time()
        row = run_episode(task)
        phases["episode"] = time.perf_counter() - mark
        cpu = time.process_time() - cpu
        process_cpu = time.process_time()
        mark = time.perf_counter()
        with quiet_stdout():
            raw = _pybullet_rate(task["scene"])
        raw["total_wall_seconds"] = time.perf_counter() - mark
        if row["status"] == "crashed":
            raise SystemExit(f"episode crashed: {row['error']}")
        report = row.get("report") or {}
        simulated = float(row.get("simulated_seconds") or 0.0)
        run_seconds = float(report.get("seconds") or phases["episode"])
        phases["world_and_plugins"] = max(0.0, phases["episode"] - run_seconds)
        phases["run"] = run_seconds
        out.append({"status": row["status"], "attempts": row["attempts"], "kinds": row["kinds"],
                    "seed": row["seed"], "simulated_seconds": simulated, "phases": phases,
                    "episode_cpu_seconds": cpu, "process_cpu_seconds": process_cpu, "raw": raw,
                    "inner_real_time_factor": simulated / run_seconds if run_seconds > 0 else 0.0})
    return out


def _print(result: dict[str, Any]) -> None:
    print(f"episode ({result['family']}, {result['configuration']}, {result['repeat']} process(es), median): "
          f"{result['simulated_seconds']:.1f} s simulated in {result['process_wall_seconds']:.2f} s wall -> "
          f"real_time_factor {result['real_time_factor']:.2f}x (inside the process "
          f"{result['inner_real_time_factor']:.2f}x)")
    print(f"pybullet raw stepping, same robot and scene (median): {result['pybullet_steps_per_second']:.0f} steps/s "
          f"= {result['pybullet_real_time_factor']:.1f}x real time; episode / raw = {result['ratio_to_pybullet']:.3f} "
          f"(in CPU time {result['cpu_ratio_to_pybullet']:.3f})")
    print("wall time per phase: " + ", ".join(f"{k} {v:.2f} s" for k, v in result["phases"].items()))
    worker = result["worker"]
    print(f"worker serving {worker['episodes']} further episode(s) after a warm-up: "
          f"{worker['simulated_seconds']:.1f} s simulated in {worker['episode_seconds']:.2f} s"
          f" -> worker_real_time_factor "
          f"{result['worker_real_time_factor']:.2f}x; worker / raw = {result['worker_ratio_to_pybullet']:.3f} "
          f"(in CPU time {result['worker_cpu_ratio_to_pybullet']:.3f}); "
          f"same outcomes as the fresh processes: {'yes' if worker['same_outcomes_as_fresh'] else 'NO'}")


if __name__ == "__main__":  # the timed child process
    print(json.dumps(child(sys.argv[1])))
