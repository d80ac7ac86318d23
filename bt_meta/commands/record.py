"""``bt-meta record FILE --problem P``: run the nominal plan in the simulator as the instructor's demonstration and
store its trace in the episodic memory.

Offers:

* :func:`register` -- adds ``record FILE [--problem P] [--variant V] [--seed S] [--memory PATH] [--json]
  [--max-ticks N] [--grounding FILE] [--robot R] [--scene FILE] [--world sim|ros2] [--ros2 CONFIG.yaml]
  [--check-expectations] [--plugins DIR] [--no-entry-points] [--report FILE.html]``
* :func:`record` -- the handler
* :func:`demonstrate` -- the same from Python: run and store one demonstration, return a :class:`Demonstration`
* :class:`DemonstrationFailed` -- a demonstration that did not succeed (nothing stored; the CLI exits 1)
* :data:`MEMORY_EXPECTATIONS` -- the shipped expectation plugins a demonstration runs without

The problem is planned and compiled with a Monitor around every primitive and ticked on a
:class:`~bt_meta.world.simulation.sim_world.SimWorld` (headless) with a :class:`~bt_meta.memory.recorder.TraceRecorder`
registered (``--world ros2``: a :class:`~bt_meta.ros2.world.RosWorld`, the demonstration acted through ROS 2,
docs/ros2.md); at the end the trace is written in one transaction and its episode id printed with its steps. A
demonstration teaches the expectations, so it is not checked against the memory's grid-map and keypoint
expectations (``--check-expectations`` keeps them); preconditions and skills are checked as in any run. A
demonstration that fails is refused: nothing is stored, the failure is printed and the exit status is 1.
``--report FILE.html`` writes its page as ``bt-meta run --report`` does (:class:`~bt_meta.runs.report.RunPage`),
also for a refused demonstration; an unwritable path is exit 2 once the stored episode is printed.
``--json`` prints ``{episode_id, memory, task, problem, variant, seed, outcome, steps: [{index, action, args,
node_id, parent_task, parent_node, objects, grid_maps}], expectations, ticks, seconds, failures}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from py_trees.common import Status

from bt_meta.commands._common import print_json
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.commands._world_args import add_ros2_arguments, add_world_arguments, world_factory, world_options
from bt_meta.errors import BtMetaError, PlanningError, UserInputError
from bt_meta.memory import add_memory_argument, resolve_memory_path

#: Expectation plugins whose expectations come from the memory a demonstration is about to teach.
MEMORY_EXPECTATIONS = ("gridmap_expectations", "keypoint_expectations")
RECORDER_NAME = "bt_meta_demonstration_recorder"
PAGE_NAME = "bt_meta_demonstration_page"


class DemonstrationFailed(BtMetaError):
    """The demonstration did not succeed, so it was not stored."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "record", help="run a problem's nominal plan in the simulator and store it as a demonstration")
    parser.add_argument("file", help="YAML task file")
    parser.add_argument("--problem", help="problem name (required when the file has several)")
    parser.add_argument("--variant", help="scene variant (default: the grounding file's for the problem, else nominal)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    parser.add_argument("--max-ticks", type=int, default=5000, help="give up after this many ticks (default 5000)")
    parser.add_argument("--grounding", help="grounding file (default: poses/<domain>.yaml beside FILE or shipped)")
    parser.add_argument("--check-expectations", action="store_true",
                        help="keep the memory's grid-map and keypoint expectations switched on while demonstrating")
    parser.add_argument("--json", action="store_true", help="print one JSON object with the stored episode")
    parser.add_argument("--report", metavar="FILE.html",
                        help="write the demonstration's HTML page (steps, failures, goal on the true state, trees)")
    add_world_arguments(parser)
    add_ros2_arguments(parser)
    add_memory_argument(parser)
    add_plugin_arguments(parser)
    parser.set_defaults(func=record)


@dataclass
class Demonstration:
    """A stored demonstration: the trace as read back from the memory, and what it took."""

    episode_id: int
    trace: Any
    ticks: int
    seconds: float
    recording_seconds: float


def demonstrate(
    file: str | Path,
    problem: str | None,
    memory: Any,
    *,
    variant: str | None = None,
    seed: int = 0,
    max_ticks: int = 5000,
    grounding: str | Path | None = None,
    plugins: Any = None,
    check_expectations: bool = False,
    robot: Any = None,
    scene: str | Path | None = None,
    page: Any = None,
    make_world: Any = None,
) -> Demonstration:
    """Run ``problem`` of task file ``file`` in the simulator as a demonstration and store it in ``memory`` (an open
    writable :class:`~bt_meta.memory.EpisodicMemory`). ``plugins``: a plugin host (default: built-ins, entry
    points and the project's plugins folder). Raises :class:`DemonstrationFailed` when the run does not succeed
    (nothing is stored); input errors are the loaders' :class:`~bt_meta.errors.UserInputError` s. ``page``: a
    :class:`~bt_meta.runs.report.RunPage` that watches the run (its page is the caller's to write). ``make_world``:
    the world class (default :class:`~bt_meta.world.simulation.sim_world.SimWorld`; the CLI's ``world_factory``)."""
    from bt_meta.htn import load_task_file
    from bt_meta.plugins import create_plugin_host
    from bt_meta.world.simulation.sim_world import load_grounding

    if max_ticks < 1:
        raise UserInputError("--max-ticks must be at least 1")
    task_file = load_task_file(file)
    chosen = task_file.problem(problem)  # unknown names list the known ones
    ground = load_grounding(task_file.domain.name, file, grounding)
    ground.problem(chosen.name)
    if plugins is None:
        plugins = create_plugin_host(project_file=file)
    removed: list[tuple[str, Any, str]] = []
    if not check_expectations:
        for name in MEMORY_EXPECTATIONS:
            if name in plugins.plugin_names():
                removed.append((name, plugins.manager.get_plugin(name), plugins.sources.get(name, "")))
                plugins.unregister(name)
    try:
        return _demonstrate(file, chosen, task_file, ground, memory, variant, seed, max_ticks, plugins,
                            check_expectations, robot, scene, page, make_world)
    finally:  # the caller's host is as it was
        for name, plugin, source in removed:
            plugins.register(plugin, name, source=source)


def _demonstrate(file: str | Path, chosen: Any, task_file: Any, ground: Any, memory: Any, variant: str | None,
                 seed: int, max_ticks: int, plugins: Any, check_expectations: bool,
                 robot: Any = None, scene: str | Path | None = None, page: Any = None,
                 make_world: Any = None) -> Demonstration:
    from bt_meta.memory.recorder import TraceRecorder
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    started = time.perf_counter()
    with quiet_stdout():
        world = (make_world or SimWorld)(task_file.domain, chosen, ground, variant=variant, seed=seed, robot=robot,
                                         scene=scene)
    try:
        recorder = TraceRecorder(memory, variant=world.variant, seed=seed,
                                 config={"demonstration": True, "scene": world.scene.name})
        plugins.register(recorder, RECORDER_NAME, source="bt-meta record")
        if page is not None:
            plugins.register(page.capture, PAGE_NAME, source="bt-meta record --report")
            page.start(world)
        try:
            try:
                harness = TreeHarness.from_file(file, chosen.name, world=world, plugins=plugins)
            except PlanningError as error:
                raise DemonstrationFailed(f"{chosen.name}: no plan to demonstrate ({error}); nothing stored") from None
            if check_expectations:
                harness.run.memory = memory
            recorder.tree = harness.compiled.plan_result.tree
            if page is not None:  # one segment: the tree ticked here, with the statuses its step events report
                from bt_meta.runs.capture import Segment

                page.capture.segments.append(Segment(1, harness.root, 0))
            status = Status.RUNNING
            while status is Status.RUNNING and harness.run.tick_count < max_ticks:
                status = harness.tick()
            harness.run.finish(status)
            ticks = harness.run.tick_count
            failures = [f.to_dict() for f in harness.failures]
            harness.close()
        finally:
            plugins.unregister(RECORDER_NAME)
            if page is not None:
                plugins.unregister(PAGE_NAME)
        seconds = time.perf_counter() - started
        if page is not None:
            page.finish(file, task_file, chosen, world, {
                "file": str(file), "problem": chosen.name, "scene": world.scene.name, "robot": world.sim.robot.name,
                "variant": world.variant, "seed": seed, "status": status.value, "failures": failures, "ticks": ticks,
                "plan": [" ".join((p.name, *p.args)) for p in harness.compiled.plan_result.plan],
                "run_seconds": round(seconds, 3)}, memory)
        if recorder.error is not None:
            raise recorder.error
        if status is not Status.SUCCESS or recorder.episode_id is None:
            raise DemonstrationFailed(_refusal(chosen.name, world.variant, status, ticks, failures))
        return Demonstration(recorder.episode_id, memory.trace(recorder.episode_id), ticks, seconds,
                             recorder.seconds)
    finally:
        world.close()


def record(args: argparse.Namespace) -> int:
    from bt_meta.htn import load_task_file
    from bt_meta.memory import EpisodicMemory
    from bt_meta.world.simulation.sim_world import load_grounding

    if args.max_ticks < 1:
        raise UserInputError("--max-ticks must be at least 1")
    # Bad input is reported before the memory file is created.
    task_file = load_task_file(args.file)
    problem = task_file.problem(args.problem)
    load_grounding(task_file.domain.name, args.file, args.grounding).problem(problem.name)
    options = world_options(args)
    make_world = world_factory(args)
    plugins = plugin_host_from_args(args, args.file)
    page = None
    if args.report:
        from bt_meta.runs.report import RunPage

        page = RunPage("bt-meta record")
    with EpisodicMemory.open(resolve_memory_path(args, writing=True)) as memory:
        memory.require_sound()
        try:
            shown = demonstrate(args.file, args.problem, memory, variant=args.variant, seed=args.seed,
                                max_ticks=args.max_ticks, grounding=args.grounding, plugins=plugins,
                                check_expectations=args.check_expectations, page=page, make_world=make_world,
                                **options)
        except DemonstrationFailed:
            if page is not None and page.run:  # the page of a refused demonstration is where to look first
                try:
                    print(f"report: {page.write(args.report)} ({page.verdict})", file=sys.stderr)
                except UserInputError as error:
                    print(f"bt-meta: {error}", file=sys.stderr)
            raise
        code = _report(args, memory, shown.trace, shown.ticks, shown.seconds, shown.recording_seconds)
        if page is not None:  # after the stored episode is printed: a bad path loses none of it
            written = page.write(args.report)
            if not args.json:
                print(f"report: {written} ({page.verdict})")
        return code


def _refusal(problem: str, variant: str, status: Status, ticks: int, failures: list[dict[str, Any]]) -> str:
    if status is Status.RUNNING:
        why = f"still running after {ticks} ticks (--max-ticks)"
    elif failures:
        first = failures[0]
        where = f"step {first['step']} {first.get('action') or ''}{tuple(first.get('args') or ())}" \
            if first.get("step") is not None else (first.get("node_id") or "the tree")
        why = f"{first['kind']} failure at {where}: {first['message']}"
    else:
        why = f"the tree ended {status.value}"
    return f"demonstration of {problem} ({variant}) failed, nothing stored: {why}"


def _report(args: argparse.Namespace, memory: Any, trace: Any, ticks: int, seconds: float,
            recording: float) -> int:
    episode = trace.episode
    steps = [{
        "index": s.index, "action": s.action, "args": list(s.args), "node_id": s.node_id,
        "parent_task": s.parent_task, "parent_node": s.parent_node, "task_index": s.task_index,
        "objects": len(s.state.objects),
        "grid_maps": [{"object": g.object_name, "colour": g.colour, "shape": g.shape} for g in s.state.grid_maps],
    } for s in trace.steps]
    if args.json:
        print_json({
            "episode_id": episode.id, "memory": str(memory.path), "task": episode.task, "problem": episode.problem,
            "task_file": episode.task_file, "variant": episode.variant, "seed": episode.seed,
            "outcome": episode.outcome, "steps": steps, "expectations": len(trace.expectations), "ticks": ticks,
            "seconds": round(seconds, 3), "recording_seconds": round(recording, 3),
        })
        return 0
    print(f"recorded episode {episode.id}: {episode.task} (problem {episode.problem}, variant {episode.variant}, "
          f"seed {episode.seed}), {len(steps)} steps, outcome {episode.outcome}")
    for step in steps:
        call = f"{step['action']}({', '.join(step['args'])})"
        maps = ", ".join(f"{m['object']} {m['colour']} {m['shape']}" for m in step["grid_maps"])
        print(f"  {step['index']:>3}  {step['node_id'] or '-':<5} {call:<28} in {step['parent_task'] or '-'}"
              f" ({step['parent_node'] or '-'})  {step['objects']} objects" + (f", grid-map {maps}" if maps else ""))
    print(f"{len(trace.expectations)} expectations in E_db; {ticks} ticks in {seconds:.2f} s "
          f"(recording {recording:.3f} s) -> {memory.path}")
    return 0


__all__ = ["MEMORY_EXPECTATIONS", "Demonstration", "DemonstrationFailed", "demonstrate", "record", "register"]
