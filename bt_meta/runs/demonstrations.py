"""Recording demonstrations: a task file's nominal problem run monitored, its success stored as a trace.

The demo and the campaigns both record the instructor's runs this way before any variant runs, so it lives below
both of them.

Offers:

* :class:`Demonstration` -- a nominal problem recorded as the instructor's trace (task file, problem, seed)
* :class:`RecordOutcome` -- what recording one gave: ``recorded``, ``reused`` or ``failed``, with the reason
* :func:`record_demonstration` -- run and store one demonstration
* :func:`memory_environment` -- point ``BT_META_MEMORY`` at a file for the plugins that find the memory themselves
* :func:`sim_world` -- the simulated world of a task file's problem (variant, seed, robot), jittered by the seed
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bt_meta.judge.noise import jitter
from bt_meta.runs.capture import Progress, RunCapture

__all__ = ["Demonstration", "RecordOutcome", "memory_environment", "perception_plugins", "record_demonstration",
           "sim_world"]


@dataclass(frozen=True)
class Demonstration:
    family: str
    task_file: str
    problem: str
    seed: int

    @property
    def label(self) -> str:
        return f"{self.task_file.removesuffix('.yaml')} {self.problem} (seed {self.seed})"


@contextlib.contextmanager
def memory_environment(path: Path) -> Iterator[None]:
    """Point ``BT_META_MEMORY`` at ``path`` (plugins that find the memory themselves read it), then restore it."""
    from bt_meta.memory import ENV_VAR

    saved = os.environ.get(ENV_VAR)
    os.environ[ENV_VAR] = str(path)
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop(ENV_VAR, None)
        else:
            os.environ[ENV_VAR] = saved


@dataclass
class RecordOutcome:
    demonstration: Demonstration
    status: str
    """``recorded``, ``reused`` (the memory had it) or ``failed``."""
    episode_id: int | None = None
    steps: int = 0
    ticks: int = 0
    seconds: float = 0.0
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = self.demonstration
        return {"task_file": d.task_file, "problem": d.problem, "seed": d.seed, "status": self.status,
                "episode_id": self.episode_id, "steps": self.steps, "ticks": self.ticks,
                "seconds": round(self.seconds, 3), "message": self.message}


def sim_world(task_path: Path, problem: str, variant: str | None, seed: int, robot: Any = None
              ) -> tuple[Any, Any, Any]:
    """The task file, its problem and a SimWorld of it, jittered by ``seed`` (closed again if that fails)."""
    from bt_meta.htn import load_task_file
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(task_path)
    chosen = task_file.problem(problem)
    with quiet_stdout():
        world = SimWorld(task_file.domain, chosen, load_grounding(task_file.domain.name, task_path),
                         variant=variant, seed=seed, robot=robot)
    try:
        jitter(world, seed)
    except BaseException:
        world.close()
        raise
    return task_file, chosen, world


def _already_recorded(memory: Any, demo: Demonstration, task: str) -> int | None:
    for summary in memory.episodes(task=task, outcome="success"):
        episode = summary.episode
        if episode.problem == demo.problem and episode.seed == demo.seed and (episode.variant in (None, "nominal")):
            return episode.id
    return None


def record_demonstration(demo: Demonstration, memory: Any, progress: Progress, *, max_ticks: int = 6000,
                         robot: Any = None) -> RecordOutcome:
    """Run ``demo``'s nominal problem tick by tick (monitored, no repairs) with the trace recorder; a success is
    written to ``memory`` as one trace."""
    from py_trees.common import Status

    from bt_meta.memory.recorder import TraceRecorder, root_task_name
    from bt_meta.plugins import create_plugin_host
    from bt_meta.resources import trees_dir
    from bt_meta.testing import TreeHarness

    started = time.perf_counter()
    task_path = trees_dir() / demo.task_file
    _, problem, world = sim_world(task_path, demo.problem, None, demo.seed, robot)
    try:
        existing = _already_recorded(memory, demo, root_task_name(problem))
        if existing is not None:
            return RecordOutcome(demo, "reused", existing, message=f"episode {existing} is already in memory")
        recorder = TraceRecorder(memory, seed=demo.seed, variant="nominal", task_file=str(task_path))
        capture = RunCapture(progress, world, label=f"record {demo.label}", echo=False)
        # The instructor's run: perception observes, the recorder writes; no expectation compares against a memory
        # still being filled, so every demonstration stands on its own.
        host = create_plugin_host(project_file=task_path, entry_points=False,
                                  plugins=[*perception_plugins(), ("trace_recorder", recorder),
                                           ("demo_capture", capture)])
        harness = TreeHarness.from_file(task_path, demo.problem, world=world, plugins=host)
        status = Status.RUNNING
        while status is Status.RUNNING and harness.run.tick_count < max_ticks:
            status = harness.tick()
        harness.run.finish(status)
        harness.close()
        progress.done()
        if recorder.error is not None:
            return RecordOutcome(demo, "failed", None, len(capture.steps), capture.ticks,
                                 time.perf_counter() - started, f"not stored: {recorder.error}")
        if status is not Status.SUCCESS or recorder.episode_id is None:
            failures = "; ".join(f.summary() for f in harness.run.failures) or recorder.skipped or status.value
            return RecordOutcome(demo, "failed", None, len(capture.steps), capture.ticks,
                                 time.perf_counter() - started, f"{status.value}: {failures}")
        return RecordOutcome(demo, "recorded", recorder.episode_id, len(capture.steps), capture.ticks,
                             time.perf_counter() - started)
    finally:
        world.close()


def perception_plugins() -> list[tuple[str, Any]]:
    import bt_meta_plugins.camera_perception as camera
    import bt_meta_plugins.ground_truth_perception as truth

    return [("ground_truth_perception", truth), ("camera_perception", camera)]
