"""The demo scenario, end to end: record demonstrations, run the variants with repairs, run them again.

On the episodic memory ``DIR/memory.sqlite`` (created when absent, reused when present):

1. **record** the instructor's demonstrations (letters A and H, magnetic-attach nominal with a few seeds, the
   housing nominal) through the :class:`~bt_meta.memory.recorder.TraceRecorder` plugin; demonstrations the memory
   already holds (same task, problem and seed) are not recorded again;
2. **run the variants** (A with substituted blocks, magnetic attach with variant poses, the upside-down housing) on
   the simulator with monitors and the meta-reasoner (:class:`~bt_meta.meta.executor.MetaExecutor`): classified
   failures, repair proposals, applied repairs, verification; a repaired run is stored as a refinement;
3. **run each variant again**: a learned refinement is used and the run needs zero repair attempts.

Progress is printed one line per step, failure and repair (:class:`~bt_meta.runs.capture.Progress`); everything
the report needs is collected in :class:`DemoResult` (``summary()`` is ``DIR/summary.json``).

Offers:

* :func:`run_demo` -- the whole scenario; returns a :class:`DemoResult`
* :func:`run_variant` -- one monitored, repaired variant run (used by the ablation experiment too)
* :class:`DemoResult`, :class:`VariantOutcome`
* :func:`record_demonstration`, :class:`RecordOutcome`, :func:`memory_environment` -- from
  :mod:`bt_meta.runs.demonstrations` (the campaigns record the same way), importable from here too
"""

from __future__ import annotations

import json
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bt_meta.configurations import CONFIGURATIONS, available_repairs, plugin_host
from bt_meta.demo.scenario import FAMILIES, VariantRun, demonstrations, variants
from bt_meta.errors import BtMetaError
from bt_meta.runs.capture import CapturingExecutor, Progress, RunCapture, top_view_png
from bt_meta.runs.demonstrations import (
    RecordOutcome,
    memory_environment,
    record_demonstration,
    sim_world,
)
from bt_meta.runs.report import gridmap_pictures, keypoint_series, tree_pictures

__all__ = ["DemoResult", "RecordOutcome", "VariantOutcome", "memory_environment", "record_demonstration",
           "run_demo", "run_variant"]

MEMORY_FILE = "memory.sqlite"

#: The plugin configuration the demo runs (``bt-meta experiment ablation`` compares it with the others).
DEMO_CONFIGURATION = "dual"


@dataclass
class VariantOutcome:
    variant: VariantRun
    pass_number: int
    report: dict[str, Any] = field(default_factory=dict)
    capture: RunCapture | None = None
    before_png: bytes | None = None
    after_png: bytes | None = None
    gridmaps: list[dict[str, Any]] = field(default_factory=list)
    keypoints: dict[str, Any] | None = None
    trees: list[dict[str, Any]] = field(default_factory=list)
    error: str | None = None
    seconds: float = 0.0
    achieved: bool | None = None
    """Ground truth from the simulator (:mod:`bt_meta.judge.success`): is the task really done?"""
    truth: str = ""

    @property
    def status(self) -> str:
        return "crashed" if self.error else str(self.report.get("status", "failed"))

    @property
    def attempts(self) -> list[dict[str, Any]]:
        return list(self.report.get("attempts") or [])

    @property
    def succeeded(self) -> bool:
        """The run reported success and the simulator's ground truth does not contradict it (a run the truth
        says failed is a false success, never counted as a success)."""
        return self.status == "success" and self.achieved is not False

    def to_dict(self) -> dict[str, Any]:
        v = self.variant
        report = self.report
        refinement = report.get("refinement_saved") or None
        return {
            "label": v.label, "family": v.family, "task_file": v.task_file, "problem": v.problem,
            "variant": v.variant, "seed": v.seed, "pass": self.pass_number, "status": self.status,
            "repaired": self.status == "success" and bool(self.attempts),
            "attempts": len(self.attempts),
            "repairs": [{"number": a.get("number"), "kind": a.get("kind"), "step": a.get("step"),
                         "action": (a.get("proposal") or {}).get("action"),
                         "plugin": (a.get("proposal") or {}).get("plugin"),
                         "score": (a.get("proposal") or {}).get("score"),
                         "change": a.get("change"), "outcome": a.get("outcome"), "seconds": a.get("seconds")}
                        for a in self.attempts],
            "failure_kinds": [f.get("kind") for f in report.get("failures") or []],
            "reported": [{k: r.get(k) for k in ("kind", "step", "action", "args", "message")}
                         for r in report.get("reported") or []],
            "stop_reason": report.get("stop_reason", ""),
            "refinements_used": list(report.get("refinements_used") or []),
            "refinement_saved": _saved(refinement),
            "initial_plan": report.get("initial_plan", []), "plan": report.get("plan", []),
            "ticks": report.get("ticks", 0), "seconds": round(self.seconds, 3), "error": self.error,
            "achieved": self.achieved, "truth": self.truth,
        }


def _saved(refinement: dict[str, Any] | None) -> str | None:
    """The learned refinement's method name, or why the repaired plan was not kept."""
    if not refinement:
        return None
    if refinement.get("saved") is False:
        return f"not kept: {refinement.get('reason')}"
    return str(refinement.get("method"))


@dataclass
class DemoResult:
    out: Path
    seed: int
    quick: bool
    fresh_memory: bool
    robot: str = "baxter"
    """The robot the demonstrations were recorded and the variants run on."""
    records: list[RecordOutcome] = field(default_factory=list)
    runs: list[VariantOutcome] = field(default_factory=list)
    refinements: list[dict[str, Any]] = field(default_factory=list)
    repair_plugins: list[str] = field(default_factory=list)
    seconds: float = 0.0
    crashed: list[str] = field(default_factory=list)

    @property
    def memory_path(self) -> Path:
        return self.out / MEMORY_FILE

    @property
    def completed(self) -> bool:
        """Every demonstration is in memory and every run ran to a status (repaired or not): the exit-0 rule."""
        return not self.crashed and all(r.status != "failed" for r in self.records)

    def summary(self) -> dict[str, Any]:
        first = [r for r in self.runs if r.pass_number == 1]
        second = [r for r in self.runs if r.pass_number == 2]
        return {
            "out": str(self.out), "memory": str(self.memory_path), "seed": self.seed, "quick": self.quick,
            "fresh_memory": self.fresh_memory, "robot": self.robot, "completed": self.completed,
            "seconds": round(self.seconds, 3),
            "repair_plugins": self.repair_plugins,
            "configuration": {"name": DEMO_CONFIGURATION, "plugins": CONFIGURATIONS[DEMO_CONFIGURATION]},
            "demonstrations": [r.to_dict() for r in self.records],
            "runs": [r.to_dict() for r in self.runs],
            "totals": {
                "variants": len(first),
                "first_pass_success": sum(r.status == "success" for r in first),
                "first_pass_repaired": sum(r.to_dict()["repaired"] for r in first),
                "first_pass_attempts": sum(len(r.attempts) for r in first),
                "first_pass_achieved": sum(bool(r.achieved) for r in first),
                "false_successes": sum(r.status == "success" and r.achieved is False for r in self.runs),
                "second_pass_success": sum(r.succeeded for r in second),
                "second_pass_zero_attempts": sum(r.succeeded and not r.attempts for r in second),
                "second_pass_using_refinements": sum(bool(r.report.get("refinements_used")) for r in second),
            },
            "refinements": self.refinements,
            "crashed": self.crashed,
        }


# -- variant runs ---------------------------------------------------------------------------------------------------


def run_variant(
    run: VariantRun,
    memory: Any,
    refinements: Any,
    progress: Progress,
    *,
    pass_number: int = 1,
    configuration: str = "dual",
    max_attempts: int = 6,
    max_seconds: float = 90.0,
    save_refinements: bool = True,
    pictures: bool = True,
    robot: Any = None,
) -> VariantOutcome:
    """One variant run with monitors and the meta-reasoner; collects what the report shows."""
    from bt_meta.meta import Limits
    from bt_meta.resources import trees_dir

    outcome = VariantOutcome(run, pass_number)
    started = time.perf_counter()
    task_path = trees_dir() / run.task_file
    task_file, problem, world = sim_world(task_path, run.problem, run.variant, run.seed, robot)
    try:
        capture = RunCapture(progress, world, label=run.label, echo=not progress.quiet)
        outcome.capture = capture
        host = plugin_host(task_path, memory, configuration=configuration, seed=run.seed,
                           extra=[("demo_capture", capture)])
        if pictures:
            outcome.before_png, _ = top_view_png(world)
        executor = CapturingExecutor(
            task_file.domain, problem, world, host, capture=capture,
            limits=Limits(max_attempts=max_attempts, max_seconds=max_seconds), refinements=refinements,
            save_refinements=save_refinements, task_file=task_file, variant=run.variant, memory=memory)
        report = executor.run()
        progress.done()
        outcome.report = report.to_dict()
        from bt_meta.judge.success import success_check_file

        judge = success_check_file(FAMILIES[run.family].success_file(), task_file, problem, world.grounding,
                                   scene_objects=[o.name for o in world.scene.objects])
        outcome.achieved, outcome.truth = judge.evaluate(world)
        if pictures:
            outcome.after_png, after_view = top_view_png(world)
            outcome.gridmaps = gridmap_pictures(capture, after_view)
            outcome.trees = tree_pictures(capture)
            pair = FAMILIES[run.family].keypoint_pair
            if pair is not None:
                outcome.keypoints = keypoint_series(capture, memory, problem, pair, report.to_dict())
    except BtMetaError as error:
        outcome.error = f"{type(error).__name__}: {error}"
    except Exception as error:  # a crash of one run is reported in the summary, the demo goes on
        outcome.error = f"{type(error).__name__}: {error}\n{traceback.format_exc(limit=6)}"
    finally:
        world.close()
        outcome.seconds = time.perf_counter() - started
    return outcome


# -- the scenario ---------------------------------------------------------------------------------------------------


def _print_outcome(progress: Progress, outcome: VariantOutcome) -> None:
    if outcome.error:
        progress.line(f"  => CRASHED: {outcome.error.splitlines()[0]}")
        return
    report = outcome.report
    attempts = len(outcome.attempts)
    used = report.get("refinements_used") or []
    saved = report.get("refinement_saved") or {}
    text = (f"  => {str(report.get('status')).upper()} after {attempts} repair attempt(s), {report.get('ticks')} "
            f"ticks, {outcome.seconds:.1f} s")
    if used:
        text += f"; used refinement {', '.join(used)}"
    if saved.get("method"):
        text += f"; learned refinement {saved['method']}"
    elif saved.get("saved") is False:
        text += f"; repaired plan not kept as a refinement: {saved.get('reason')}"
    if report.get("status") != "success":
        text += f"; not repaired: {report.get('stop_reason')}"
    progress.line(text)
    if outcome.achieved is not None:
        verdict = "done" if outcome.achieved else "NOT done"
        progress.line(f"     task {verdict} in the simulator: {outcome.truth}")


def run_demo(
    out: str | Path,
    *,
    seed: int = 0,
    quick: bool = False,
    progress: Progress | None = None,
    write_report: bool = True,
    robot: Any = None,
) -> DemoResult:
    """The whole scenario into ``out`` (see the module docstring); writes ``summary.json`` and ``report.html``.
    ``robot``: a robot description (or name) to run on instead of each grounding file's."""
    from bt_meta.memory import EpisodicMemory
    from bt_meta.meta import RefinementStore
    from bt_meta.world.simulation.sim_world import quiet_stdout

    progress = progress or Progress()
    started = time.perf_counter()
    with quiet_stdout():
        import pybullet  # noqa: F401  (prints its build time on import)

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    memory_path = out / MEMORY_FILE
    result = DemoResult(out, seed, quick, fresh_memory=not memory_path.exists(),
                        robot=getattr(robot, "name", robot) or "baxter")
    result.repair_plugins = ["retry_repair", *available_repairs()]
    progress.line(f"bt-meta demo: memory {memory_path} ({'new' if result.fresh_memory else 'reused'}), seed {seed}"
                  f"{', quick' if quick else ''}; repair plugins: {', '.join(result.repair_plugins)}")
    with memory_environment(memory_path), EpisodicMemory.open(memory_path) as memory, \
            RefinementStore.open(memory_path) as refinements:
        demos = demonstrations(seed, quick=quick)
        progress.line(f"\n[1/3] recording {len(demos)} demonstrations")
        for number, demo in enumerate(demos, 1):
            try:
                record = record_demonstration(demo, memory, progress, robot=robot)
            except Exception as error:
                record = RecordOutcome(demo, "failed", message=f"{type(error).__name__}: {error}")
                result.crashed.append(f"record {demo.label}: {record.message}")
            result.records.append(record)
            detail = (f"episode {record.episode_id}, {record.steps} steps, {record.ticks} ticks, "
                      f"{record.seconds:.1f} s" if record.status == "recorded" else record.message)
            progress.line(f"  ({number}/{len(demos)}) {demo.label:<36} {record.status.upper():<9} {detail}")
        runs = variants(seed, quick=quick)
        for pass_number in (1, 2):
            title = ("running the variants with monitors and the meta-reasoner" if pass_number == 1 else
                     "running each variant again: learned refinements, zero repair attempts expected")
            progress.line(f"\n[{pass_number + 1}/3] {title}")
            for number, run in enumerate(runs, 1):
                progress.line(f"\n  ({number}/{len(runs)}) {FAMILIES[run.family].task_file} problem {run.problem}, "
                              f"variant {run.variant}, seed {run.seed}")
                outcome = run_variant(run, memory, refinements, progress, pass_number=pass_number,
                                      configuration=DEMO_CONFIGURATION, robot=robot)
                if outcome.error:
                    result.crashed.append(f"{run.label} pass {pass_number}: {outcome.error.splitlines()[0]}")
                result.runs.append(outcome)
                _print_outcome(progress, outcome)
        result.refinements = [r.to_dict() for r in refinements.list()]
    result.seconds = time.perf_counter() - started
    (out / "summary.json").write_text(json.dumps(result.summary(), indent=2, default=str) + "\n", encoding="utf-8")
    if write_report:
        from bt_meta.demo.report import write_report as write_html

        write_html(result, out / "report.html")
    return result
