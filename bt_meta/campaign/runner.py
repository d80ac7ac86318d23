"""``campaign run``: every (variant, configuration, seed) of a campaign as one episode, on a pool or on Ray.

The driver reads the manifest, opens the campaign database (refusing one of another version or manifest),
records the demonstration memory once (into a temporary file renamed when complete, so a killed recording is
simply redone), then hands the episodes not yet in the database to a local process pool (``spawn``ed workers,
``--workers``, default the core count) or, with ``--ray``, to Ray tasks; results stream back as they finish and
the driver -- the only writer -- inserts each one in its own transaction and writes its run report to
``DIR/episodes/``. Killed at any moment, the same command resumes: finished episodes are in the database and are
not run again, the ones in flight are run again. A progress bar with ETA goes to stderr (tqdm). Pool and Ray
workers (and the driver with one worker) serve many episodes each, loading the immutable models once per process
(:mod:`bt_meta.model_cache`); every episode's world is fresh.

Offers:

* :func:`run_campaign` -- the driver; returns ``{"episodes": [...], "summary": {...}}``
* :func:`ensure_memory` -- the campaign's demonstration memory, recorded once
* :func:`check_ray_address` -- a Ray address that does not answer is a :class:`RayAddressError`
* :func:`episode_key` / :func:`report_path`
"""

from __future__ import annotations

import os
import socket
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from bt_meta.errors import UserInputError

__all__ = ["DemonstrationError", "RayAddressError", "check_ray_address", "ensure_memory", "episode_key", "report_path",
           "run_campaign"]

MEMORY = "memory.sqlite"
EPISODES = "episodes"


class RayAddressError(UserInputError):
    """``--ray ADDRESS`` that does not answer, or Ray not installed."""


def episode_key(row: dict[str, Any]) -> str:
    return f"{row['variant']}__{row['configuration']}__{row['seed']}"


def report_path(folder: str | Path, row: dict[str, Any]) -> Path:
    return Path(folder) / EPISODES / f"{episode_key(row)}.json"


class DemonstrationError(UserInputError):
    """A demonstration of the campaign's task that does not succeed: the task as written fails, no episode runs."""


def ensure_memory(folder: Path, manifest: dict[str, Any], *, echo: Callable[[str], None] = print) -> Path:
    """``DIR/memory.sqlite``, recording the family's demonstrations first (on the campaign's robot) when it is not
    there; a demonstration that fails stops everything, naming it (:class:`DemonstrationError`)."""
    from bt_meta.campaign.families import family_of_manifest
    from bt_meta.campaign.manifest import manifest_robot
    from bt_meta.demo.capture import Progress
    from bt_meta.demo.runner import memory_environment, record_demonstration
    from bt_meta.demo.scenario import Demonstration
    from bt_meta.memory import EpisodicMemory

    path = folder / MEMORY
    if path.is_file():
        return path
    partial = folder / f".{MEMORY}.partial"
    for leftover in folder.glob(f".{MEMORY}.partial*"):
        leftover.unlink()
    chosen = family_of_manifest(manifest)
    robot = manifest_robot(manifest) if manifest.get("robot") else None
    started = time.perf_counter()
    demos = [Demonstration(chosen.name, chosen.task_file, problem, int(manifest["seed"]) + k)
             for problem, repeats in chosen.demonstration_list() for k in range(repeats)]
    try:
        with memory_environment(partial), EpisodicMemory.open(partial) as memory:
            for demo in demos:
                outcome = record_demonstration(demo, memory, Progress(quiet=True), robot=robot)
                if outcome.status == "failed":
                    raise DemonstrationError(f"the demonstration {demo.label} failed, so no episode runs: "
                                             f"{outcome.message}", chosen.task_file)
    except BaseException:
        for leftover in folder.glob(f".{MEMORY}.partial*"):
            leftover.unlink()
        raise
    os.replace(partial, path)
    for leftover in folder.glob(f".{MEMORY}.partial*"):  # SQLite's -wal / -shm companions
        leftover.unlink()
    echo(f"recorded {len(demos)} demonstration(s) into {path} ({time.perf_counter() - started:.1f} s)")
    return path


def check_ray_address(address: str, timeout: float = 3.0) -> None:
    """Raise :class:`RayAddressError` naming ``address`` when nothing listens there (``auto`` is always fine)."""
    if address == "auto":
        return
    text = address.split("://", 1)[-1]
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise RayAddressError(f"--ray {address!r}: give HOST:PORT (or ray://HOST:PORT, or auto)", "<command line>")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as error:
        raise RayAddressError(f"--ray {address!r}: no Ray cluster answers there ({error.strerror or error})",
                              "<command line>") from None


def _pool_results(tasks: Sequence[dict[str, Any]], workers: int, function: Callable[[dict[str, Any]], Any] | None = None
                  ) -> Iterator[Any]:
    """``function`` (default :func:`~bt_meta.campaign.episode.run_episode`) of every task, as they finish."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from bt_meta.campaign.episode import run_episode

    run_episode = function or run_episode  # type: ignore[assignment]
    if workers <= 1:
        for task in tasks:
            yield run_episode(task)
        return
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = [pool.submit(run_episode, task) for task in tasks]
        for future in as_completed(futures):
            yield future.result()
    finally:
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:  # the episodes still in flight are run again by the next run
            if process.is_alive():
                process.terminate()


def _ray_results(tasks: Sequence[dict[str, Any]], address: str, workers: int | None) -> Iterator[dict[str, Any]]:
    check_ray_address(address)
    try:
        import ray
    except ImportError:
        raise RayAddressError("--ray needs Ray: pip install 'bt-meta[ray]'", "<command line>") from None
    from bt_meta.campaign.episode import run_episode

    started_here = not ray.is_initialized()
    if started_here:
        options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                   "configure_logging": False}
        if address == "auto":
            options["num_cpus"] = workers or os.cpu_count() or 1
            ray.init(**options)
        else:
            ray.init(address=address, **options)
    try:
        remote = ray.remote(num_cpus=1)(run_episode)
        pending = [remote.remote(task) for task in tasks]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                yield ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()


def _terminate_as_interrupt() -> None:
    """SIGTERM unwinds like Ctrl-C, so the pool's workers are stopped rather than left running orphaned."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        def interrupt(signum: int, frame: Any) -> None:
            raise KeyboardInterrupt

        signal.signal(signal.SIGTERM, interrupt)


def run_campaign(folder: str | Path, *, configurations: Sequence[str] = ("dual", "symbolic", "low_level", "retry"),
                 seeds: int = 1, workers: int | None = None, ray_address: str | None = None,
                 perfect_sensing: bool = False, progress: bool = True, echo: Callable[[str], None] | None = None,
                 limit: int | None = None, robot: str | None = None) -> dict[str, Any]:
    """Run (or resume) the campaign in ``folder`` on its robot (``robot``, if given, must be it: another is refused
    before anything runs); ``limit`` stops after that many new episodes (tests)."""
    import json

    from bt_meta.campaign.database import CampaignDatabase
    from bt_meta.campaign.episode import episode_task
    from bt_meta.campaign.manifest import check_robot, manifest_digest, read_manifest
    from bt_meta.campaign.stats import summarise
    from bt_meta.world.simulation.sim_world import quiet_stdout

    with quiet_stdout():
        import pybullet  # noqa: F401  (prints its build time on import: keeps --json clean)
    say = echo or (lambda text: print(text, file=sys.stderr, flush=True))
    folder = Path(folder)
    manifest = read_manifest(folder)
    check_robot(manifest, robot, folder)
    if ray_address is not None:
        check_ray_address(ray_address)
    workers = workers or os.cpu_count() or 1
    _terminate_as_interrupt()
    database = CampaignDatabase.open(folder, manifest_digest(folder))
    try:
        database.check_sensing("perfect" if perfect_sensing else "perceived")
        ensure_memory(folder, manifest, echo=say)
        done = database.done()
        tasks = [episode_task(folder, manifest, variant, configuration, seed, perfect_sensing=perfect_sensing)
                 for variant in manifest["variants"] for configuration in configurations for seed in range(seeds)]
        todo = [t for t in tasks if (t["variant"], t["configuration"], t["seed"]) not in done]
        if limit is not None:
            todo = todo[:limit]
        say(f"campaign {folder}: {len(tasks)} episodes, {len(tasks) - len(todo)} already done, {len(todo)} to run "
            f"on {'Ray ' + ray_address if ray_address else f'{workers} worker(s)'}")
        (folder / EPISODES).mkdir(exist_ok=True)
        results = _ray_results(todo, ray_address, workers) if ray_address else _pool_results(todo, workers)
        bar = None
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), unit="episode", file=sys.stderr, dynamic_ncols=True)
        try:
            for row in results:
                report = row.pop("report", {})
                row["run_report"] = f"{EPISODES}/{episode_key(row)}.json"
                report_path(folder, row).write_text(json.dumps({**row, "report": report}, indent=1, default=str),
                                                    encoding="utf-8")
                database.add(row)
                if bar is not None:
                    bar.set_postfix_str(f"{row['variant']} {row['configuration']} {row['status']}", refresh=False)
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()
        wanted = {(t["variant"], t["configuration"], t["seed"]) for t in tasks}
        rows = [r for r in database.rows() if (r["variant"], r["configuration"], int(r["seed"])) in wanted]
    finally:
        database.close()
    episodes = [{k: r.get(k) for k in ("variant", "configuration", "seed", "expected", "status", "success",
                                       "attempts", "kinds", "repairs", "loop", "stop_reason", "second_exposure",
                                       "seconds", "simulated_seconds", "run_report", "error")} for r in rows]
    return {"episodes": episodes, "summary": summarise(rows, configurations=configurations)}
