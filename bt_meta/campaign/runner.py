"""``campaign run``: every (variant, configuration, seed) of a campaign as one episode, on a pool or on Ray.

The driver reads the manifest, opens the campaign database (refusing one of another version or manifest),
records the demonstration memory once (into a temporary file renamed when complete, so a killed recording is
simply redone), then hands the episodes not yet in the database to a local process pool (``spawn``ed workers,
``--workers``, default the core count) or, with ``--ray``, to Ray tasks; results stream back as they finish and
the driver -- the only writer -- inserts each one in its own transaction and writes its run report to
``DIR/episodes/``. Killed at any moment, the same command resumes: finished episodes are in the database and are
not run again, the ones in flight are run again. On Ray the driver ships what an episode reads (the memory, the
scene's text), so nodes need bt-meta but not the campaign directory; an episode whose node dies is submitted
again, and a result is stored once per episode key whatever arrives. A progress bar with ETA goes to stderr
(tqdm). Pool and Ray workers (and the driver with one worker) serve many episodes each, loading the immutable models
once per process (:mod:`bt_meta.model_cache`); every episode's world is fresh.

Offers:

* :func:`run_campaign` -- the driver; returns ``{"episodes": [...], "summary": {...}}``
* :func:`ensure_memory` -- the campaign's demonstration memory, recorded once
* :func:`check_ray_address` -- a Ray address that does not answer is a :class:`RayAddressError`, within seconds
* :class:`CampaignIncomplete` -- episodes no Ray node could finish
* :func:`episode_key` / :func:`report_path`
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["CampaignIncomplete", "DemonstrationError", "RayAddressError", "check_ray_address", "ensure_memory",
           "episode_key", "report_path", "run_campaign"]

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
    from bt_meta.memory import EpisodicMemory
    from bt_meta.runs.capture import Progress
    from bt_meta.runs.demonstrations import Demonstration, memory_environment, record_demonstration

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
    """Raise :class:`RayAddressError` naming ``address`` unless a Ray head (a gRPC server) answers there within
    ``timeout`` seconds (``auto`` is always fine): nothing listening, or a listener that never speaks gRPC, which
    ``ray.init`` would wait on for minutes."""
    if address == "auto":
        return
    text = address.split("://", 1)[-1]
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise RayAddressError(f"--ray {address!r}: give HOST:PORT (or ray://HOST:PORT, or auto)", "<command line>")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout) as connection:
            if "://" not in address:  # a GCS speaks HTTP/2: its SETTINGS frame answers the client preface
                connection.settimeout(timeout)
                connection.sendall(_HTTP2_PREFACE)
                frame = connection.recv(9)
                if len(frame) < 4 or frame[3] != 0x4:
                    raise OSError("the server there does not speak gRPC: not a Ray head")
    except OSError as error:
        reason = (f"no answer within {timeout:g} s" if isinstance(error, TimeoutError)
                  else error.strerror or str(error))
        raise RayAddressError(f"--ray {address!r}: no Ray cluster answers there ({reason})",
                              "<command line>") from None


_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 0x4, 0, 0, 0, 0, 0])
"""The HTTP/2 client connection preface and an empty SETTINGS frame (RFC 9113, 3.4)."""


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


RAY_RESUBMITS = 3
"""The driver submits an episode again this many times when Ray could not finish it (its worker or node died, its
result was lost with its node). Ray's own task retries are off, so every loss is seen and said by the driver."""


class CampaignIncomplete(BtMetaError):
    """Episodes that no Ray node finished: the others are stored, the same command runs these again."""


def _ray_episode(task: dict[str, Any], memory: bytes, scene: str) -> dict[str, Any]:
    """:func:`~bt_meta.campaign.episode.run_episode` on a Ray node, which need not see the campaign directory: the
    memory and the variant's scene come with the task and are written into a private scratch folder."""
    import tempfile

    from bt_meta.campaign.episode import run_episode

    with tempfile.TemporaryDirectory(prefix="bt_meta_ray_") as scratch:
        memory_path = Path(scratch) / "memory.sqlite"
        memory_path.write_bytes(memory)
        scene_path = Path(scratch) / Path(task["scene"]).name
        scene_path.write_text(scene, encoding="utf-8")
        row = run_episode({**task, "memory": str(memory_path), "scene": str(scene_path)})
    return row


def _ray_results(tasks: Sequence[dict[str, Any]], address: str, workers: int | None,
                 echo: Callable[[str], None] = print) -> Iterator[dict[str, Any]]:
    """Every task as a Ray task, results as they finish. The driver ships what an episode reads (the memory once,
    through the object store; each scene's text) and keeps the results: workers write nothing. A task whose worker
    or node dies is submitted again (:data:`RAY_RESUBMITS` times at most); an episode still without a result is
    named in a :class:`CampaignIncomplete` once every other has finished."""
    check_ray_address(address)
    try:
        import ray
        from ray.exceptions import RayError
    except ImportError:
        raise RayAddressError("--ray needs Ray: pip install 'bt-meta[ray]'", "<command line>") from None

    started_here = not ray.is_initialized()
    if started_here:
        options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                   "configure_logging": False}
        try:
            if address != "auto":
                ray.init(address=address, **options)
            elif os.environ.get("RAY_ADDRESS"):  # a Ray job's driver, or a cluster the environment names: join it
                ray.init(**options)
            else:
                ray.init(num_cpus=workers or os.cpu_count() or 1, **options)
        except Exception as error:  # whatever ray.init raises, the cluster there cannot be used
            first = (str(error).splitlines() or [""])[0]
            raise RayAddressError(f"--ray {address!r}: cannot join the Ray cluster there ({type(error).__name__}: "
                                  f"{first})", "<command line>") from None
    pending: dict[Any, tuple[dict[str, Any], int]] = {}
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(_ray_episode)
        memories = {path: ray.put(Path(path).read_bytes()) for path in {task["memory"] for task in tasks}}

        def submit(task: dict[str, Any], tries: int) -> None:
            scene = Path(task["scene"]).read_text(encoding="utf-8")
            pending[remote.remote(task, memories[task["memory"]], scene)] = (task, tries)

        for task in tasks:
            submit(task, 0)
        lost: list[tuple[dict[str, Any], str]] = []
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                task, tries = pending.pop(ref)
                try:
                    row = ray.get(ref)
                except RayError as error:  # run_episode never raises: the worker, its node or the result is gone
                    first = (str(error).split(". ")[0].splitlines() or [""])[0]
                    reason = f"{type(error).__name__}: {first}"
                    if tries < RAY_RESUBMITS:
                        echo(f"episode {episode_key(task)} lost on the cluster ({reason}); submitted again")
                        submit(task, tries + 1)
                    else:
                        lost.append((task, reason))
                    continue
                yield row
        if lost:
            names = ", ".join(episode_key(task) for task, _ in lost[:5]) + (" ..." if len(lost) > 5 else "")
            raise CampaignIncomplete(f"{len(lost)} episode(s) never finished on the Ray cluster ({names}; "
                                     f"last: {lost[-1][1]}); the finished ones are stored: run the same command "
                                     "again to run these")
    finally:
        for ref in pending:  # stopped early: nothing of this campaign keeps running on the cluster
            with contextlib.suppress(Exception):  # a task that ended meanwhile cannot be cancelled: fine
                ray.cancel(ref, force=True)
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
        results = (_ray_results(todo, ray_address, workers, echo=say) if ray_address
                   else _pool_results(todo, workers))
        bar = None
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), unit="episode", file=sys.stderr, dynamic_ncols=True)
        try:
            for row in results:
                key = (row["variant"], row["configuration"], int(row["seed"]))
                if key in done:  # a result delivered twice (a task run again after its node was lost): kept once
                    continue
                done.add(key)
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
    from bt_meta.campaign.stats import perturbation_classes

    return {"episodes": episodes, "summary": summarise(rows, configurations=configurations,
                                                       classes=perturbation_classes(manifest))}
