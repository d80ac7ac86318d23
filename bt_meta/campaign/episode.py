"""One campaign episode: a variant under a configuration and a seed, in a fresh world, on a copy of the memory.

:func:`run_episode` takes a plain dict (:func:`episode_task`) and returns a plain dict, so it runs the same in the
driver, in a pool worker and as a Ray task; it writes nothing into the campaign directory (the driver is its only
writer). The campaign's demonstration memory is copied into a private temporary file first: a repair's learned
refinement goes into that copy, and a repaired variant is run a second time on it (the **second exposure**: a
correct system needs zero attempts then). The world is the variant's scene file with the demo's seeded start-pose
noise (:func:`bt_meta.judge.noise.jitter`) on the campaign's robot; the task is done or not by the family's
success check on the simulator's true state (:mod:`bt_meta.judge.success`). The manifest's expected outcomes are
for the start noise of :data:`~bt_meta.campaign.labeller.START_SEED`; an episode of another seed labels its
variant again for its own (:func:`seed_label`), keeping the manifest's as ``expected_as_generated``.

Offers:

* :func:`episode_task` -- the dict an episode needs
* :func:`run_episode` -- run it; returns the row the database stores
* :func:`variant_world` -- the :class:`~bt_meta.world.simulation.sim_world.SimWorld` of a variant scene file
* :func:`seed_label` -- a variant's expected outcome for an episode's own start noise
* :data:`MAX_ATTEMPTS` -- the repair attempt budget of an episode
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

__all__ = ["MAX_ATTEMPTS", "episode_task", "run_episode", "seed_label", "variant_world"]

MAX_ATTEMPTS = 6
MAX_SECONDS = 90.0
"""An episode's time budget, in CPU seconds of its process: a loaded machine does not change the outcome."""


def episode_task(folder: str | Path, manifest: dict[str, Any], variant: dict[str, Any], configuration: str,
                 seed: int, *, perfect_sensing: bool = False) -> dict[str, Any]:
    from bt_meta.campaign.manifest import manifest_robot

    folder = Path(folder).resolve()
    return {"folder": str(folder), "family": manifest["family"], "task_file": manifest["task_file"],
            "shipped": manifest.get("shipped"), "family_file": manifest.get("family_file"),
            "family_scene": manifest.get("family_scene"), "robot": manifest_robot(manifest),
            "problem": manifest["problem"], "variant": variant["name"], "scene": str(folder / variant["file"]),
            "expected": variant["expected"], "configuration": configuration, "seed": int(seed),
            "memory": str(folder / "memory.sqlite"), "perfect_sensing": perfect_sensing,
            "base_scene": manifest.get("scene")}


def seed_label(task: dict[str, Any]) -> Any:
    """The variant's :class:`~bt_meta.campaign.labeller.Label` for the start noise of the episode's seed, or
    ``None`` for the seed the manifest's labels describe: another seed starts every object up to 3 mm and 2 degrees
    elsewhere, which can carry one across a threshold of the labeller's (a distractor's reach into a letter cell).
    The family's scene stands in for a base scene path that another install of bt-meta wrote (the same file name);
    another missing one is an error naming it."""
    from bt_meta.campaign.families import shipped_dir
    from bt_meta.campaign.labeller import START_SEED
    from bt_meta.model_cache import cached, signature_or_none

    if int(task["seed"]) == START_SEED:
        return None
    # Every configuration of a campaign runs each variant and seed: the label is theirs alike, found once per
    # process (~0.3 s; keyed by the files the task names, so an edited scene or task file is labelled again).
    key = ("seed_label", *(repr(task.get(k, ...)) for k in ("family", "shipped", "family_file", "task_file", "problem",
                                                       "family_scene", "base_scene", "scene", "scene_variant",
                                                       "robot", "seed")),
           *(signature_or_none(task.get(k)) for k in ("family_file", "task_file", "family_scene", "base_scene",
                                                       "scene", "robot")),
           signature_or_none(shipped_dir() / f"{task.get('family')}.yaml"))
    return cached(key, lambda: _label_for_seed(task))


def _label_for_seed(task: dict[str, Any]) -> Any:
    from bt_meta.campaign.families import family_of_manifest
    from bt_meta.campaign.generator import VARIANT_NAME
    from bt_meta.campaign.labeller import Labeller
    from bt_meta.errors import ConfigError
    from bt_meta.world.simulation.scenes import load_scene

    chosen = family_of_manifest(task)
    base = task.get("base_scene") or chosen.scene
    if not Path(base).exists() and Path(base).suffix:
        if Path(base).stem != Path(str(chosen.scene)).stem:
            raise ConfigError(f"campaign.json: the base scene {base} is not there (labelling seed {task['seed']})")
        base = chosen.scene
    with Labeller(chosen, load_scene(base), start_seed=int(task["seed"]), robot=task.get("robot")) as labeller:
        return labeller.label(task["scene"], task.get("scene_variant", VARIANT_NAME))


def variant_world(task_path: Path, problem_name: str, scene: str | Path, variant: str | None, seed: int,
                  robot: Any = None) -> Any:
    """(task file, problem, world): the problem's grounding with its scene replaced by ``scene``, on ``robot``
    (default the grounding's)."""
    from bt_meta.htn import load_task_file
    from bt_meta.judge.noise import jitter
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(task_path)
    problem = task_file.problem(problem_name)
    grounding = load_grounding(task_file.domain.name, task_path)
    grounding = dataclasses.replace(grounding, problems={**grounding.problems,
                                                      problem.name: {"scene": str(Path(scene).resolve())}})
    with quiet_stdout():
        world = SimWorld(task_file.domain, problem, grounding, variant=variant, seed=seed, robot=robot)
    try:
        jitter(world, seed)
    except BaseException:
        world.close()
        raise
    return task_file, problem, world


def _one_run(task: dict[str, Any], memory_path: Path, *, save: bool) -> dict[str, Any]:
    from bt_meta.campaign.families import family_of_manifest
    from bt_meta.campaign.generator import VARIANT_NAME
    from bt_meta.configurations import plugin_host
    from bt_meta.memory import EpisodicMemory
    from bt_meta.meta import Limits, MetaExecutor, RefinementStore

    chosen = family_of_manifest(task)
    task_path = chosen.task_path()
    extra = []
    if not task.get("perfect_sensing", True):
        from bt_meta.sensing.perceived import perceived_plugins

        extra = perceived_plugins(int(task["seed"]))
    with EpisodicMemory.open(memory_path) as memory, RefinementStore.open(memory_path) as refinements:
        task_file, problem, world = variant_world(task_path, task["problem"], task["scene"],
                                                  task.get("scene_variant", VARIANT_NAME), int(task["seed"]),
                                                  robot=task.get("robot"))
        try:
            host = plugin_host(task_path, memory, configuration=task["configuration"], seed=int(task["seed"]),
                               extra=extra)
            executor = MetaExecutor(task_file.domain, problem, world, host,
                                    limits=Limits(max_attempts=MAX_ATTEMPTS, max_seconds=MAX_SECONDS, clock="cpu"),
                                    refinements=refinements, save_refinements=save, task_file=task_file,
                                    variant=task.get("scene_variant", VARIANT_NAME), memory=memory)
            report = executor.run().to_dict()
            judge = chosen.success_check(task_file, problem, world.grounding, [o.name for o in world.scene.objects])
            done, truth = judge.evaluate(world)
            report["simulated_seconds"] = world.total_ticks * world.tick_seconds
        finally:
            world.close()
    report["achieved"], report["truth"] = done, truth
    return report


def run_episode(task: dict[str, Any]) -> dict[str, Any]:
    """Run one episode (see the module docstring); never raises: a crash is a row with status ``crashed``."""
    from bt_meta.world.simulation.sim_world import quiet_stdout

    with quiet_stdout():
        import pybullet  # noqa: F401  (prints its build time on import: keeps --json clean)
    started = time.perf_counter()
    row: dict[str, Any] = {key: task[key] for key in ("variant", "configuration", "seed", "expected")}
    row["family"] = task["family"]
    row["sensing"] = "perceived" if not task.get("perfect_sensing", True) else "perfect"
    with tempfile.TemporaryDirectory(prefix="bt_meta_episode_") as scratch:
        copy = Path(scratch) / "memory.sqlite"
        try:
            shutil.copyfile(task["memory"], copy)
            label = seed_label(task)
            if label is not None:
                row.update(expected_as_generated=row["expected"], expected=label.expected,
                           expected_reason=label.reason)
            report = _one_run(task, copy, save=True)
            attempts = list(report.get("attempts") or [])
            success = report.get("status") == "success" and report.get("achieved") is not False
            row.update(status=str(report.get("status")), success=success, attempts=len(attempts),
                       achieved=report.get("achieved"), truth=report.get("truth"),
                       kinds=sorted({str(f.get("kind")) for f in report.get("failures") or []}),
                       repairs=[(a.get("proposal") or {}).get("plugin") for a in attempts],
                       stop_reason=report.get("stop_reason", ""),
                       loop=str(report.get("stop_reason", "")).startswith("attempt budget spent"),
                       simulated_seconds=round(float(report.get("simulated_seconds", 0.0)), 3),
                       error=None, report=report)
            saved = report.get("refinement_saved") or {}
            if success and attempts:
                # every repaired run, a refinement kept or not: one that kept none repeats its repair, and that
                # counts against the second exposure
                second = _one_run(task, copy, save=False)
                row["second_exposure"] = {
                    "status": second.get("status"), "attempts": len(second.get("attempts") or []),
                    "achieved": second.get("achieved"), "refinement_saved": bool(saved.get("method")),
                    "refinements_used": list(second.get("refinements_used") or [])}
            else:
                row["second_exposure"] = None
        except Exception as error:  # one crashed episode is a row, the campaign goes on
            row.update(status="crashed", success=False, attempts=0, kinds=[], repairs=[], stop_reason="",
                       loop=False, achieved=None, truth="", simulated_seconds=0.0, second_exposure=None,
                       error=f"{type(error).__name__}: {error}\n{traceback.format_exc(limit=8)}", report={})
    row["seconds"] = round(time.perf_counter() - started, 3)
    return row
