"""``bt-meta run FILE --problem P``: plan a task file's problem and run it tick by tick on the simulated Baxter.

Offers:

* :func:`register` -- adds ``run FILE [--problem P] [--variant V] [--seed S] [--json] [--plugins DIR]
  [--max-ticks N] [--gui] [--grounding FILE] [--robot R] [--scene FILE] [--record-rrd FILE.rrd] [--memory PATH]
  [--record] [--record-failed] [--repair] [--max-attempts N] [--groot2 [PORT]] [--groot2-host ADDRESS] [--hold]
  [--btlog FILE] [--report FILE.html]``
* :func:`run` -- the handler

The problem is planned and compiled with a Monitor around every primitive, then ticked on a
:class:`~bt_meta.world.simulation.sim_world.SimWorld` built from the grounding file (``poses/<domain>.yaml``) and the
problem's scene with the chosen variant, headless unless ``--gui``. The tick log prints one line per tick in which
some primitive changed status. ``--json`` prints ``{status, ticks, failures: [{kind, step, node_id, action, args,
evidence, message}], objects (final object states), achieved, truth, ...}``: ``achieved`` / ``truth`` are the
ground truth, the task's goal on the simulator's true state judged as campaigns judge it
(:func:`~bt_meta.runs.report.judge_world`; ``null`` with the reason when a goal predicate has no check), printed
as a "ground truth" line without ``--json``. Exit status: 0 SUCCESS, 1 FAILURE (a failed step, no
plan, or still running after ``--max-ticks``), 2 bad input (unknown problem or variant: the known ones are listed).

``--robot NAME|FILE`` runs on another robot description (default: the grounding file's ``robot:``, else the
Baxter), ``--scene FILE`` builds another scene than the grounding file's for the problem. ``--record-rrd FILE.rrd``
records the episode for the Rerun viewer (:mod:`~bt_meta.world.simulation.rerun_log`; the optional extra
``rerun``): per tick without ``--repair``, per step, failure and repair with it. With ``--world ros2``,
``--record-mcap FILE.mcap`` records the ROS 2 messages and the tree's node statuses per tick, failures and repairs
(:class:`~bt_meta.ros2.mcap_recording.McapTreeLog`).

Memory: the expectation plugins read the run's ``memory`` (``--memory PATH``, else ``$BT_META_MEMORY``, else
``./.bt-meta/memory.sqlite``; an explicit ``--memory`` file must exist unless the run writes to it). ``--record``
stores the run's trace with a :class:`~bt_meta.memory.recorder.TraceRecorder` when it succeeds (``--record-failed``:
also when it fails, with its outcome); the episode id is printed (JSON ``episode_id``). ``--repair`` runs through
the :class:`~bt_meta.meta.executor.MetaExecutor` with the plugin host, the memory and its learned refinements:
failures are diagnosed and repaired (at most ``--max-attempts``), a successful repair is saved as a refinement; it
prints the attempts and repairs (JSON gains ``attempts``, ``repairs``, ``refinement_saved``,
``refinements_used``, ``stop_reason``, ``reported``, ``initial_plan``).

``--report FILE.html`` writes the run's page (:mod:`bt_meta.runs.report`, the demo's): failures, repairs, the
goal checked on the simulator's true state (:func:`bt_meta.judge.success.success_check`; a shipped task through
its family file's ``success:``), top views, the trees as ticked, R_p / R_n of the first task's two arguments;
written after the result is printed and recorded, an unwritable path is exit 2 naming it.

Groot2: ``--groot2 [PORT]`` serves the running tree to Groot2 (with ``--repair``: each segment's tree as it
runs), ``--hold`` keeps serving after the last tick, ``--btlog FILE`` logs it for replay (docs/groot2.md; not with
``--repair``: a log holds one tree).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from py_trees.common import Status

from bt_meta.commands._common import print_json, shown_in_trace
from bt_meta.commands._groot2_args import (
    add_groot2_arguments,
    check_groot2_arguments,
    follow_groot2,
    start_groot2,
)
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.commands._world_args import add_ros2_arguments, add_world_arguments, world_factory, world_options
from bt_meta.errors import PlanningError, UserInputError
from bt_meta.memory import ENV_VAR, add_memory_argument, resolve_memory_path
from bt_meta.plugins import hookimpl


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("run", help="plan a problem and run it tick by tick in the pybullet simulator")
    parser.add_argument("file", help="YAML task file")
    parser.add_argument("--problem", help="problem name (required when the file has several)")
    parser.add_argument("--variant", help="scene variant (default: the grounding file's for the problem, else nominal)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    parser.add_argument("--max-ticks", type=int, default=5000, help="give up after this many ticks (default 5000)")
    parser.add_argument("--gui", action="store_true", help="open the pybullet window and run in real time")
    parser.add_argument("--grounding", help="grounding file (default: poses/<domain>.yaml beside FILE or shipped)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with the outcome")
    parser.add_argument("--record", action="store_true",
                        help="store this run's trace in the episodic memory when it succeeds")
    parser.add_argument("--record-failed", action="store_true",
                        help="store this run's trace even when it fails (its outcome is recorded); implies --record")
    parser.add_argument("--repair", action="store_true",
                        help="diagnose and repair failures with the meta-reasoner (memory, refinements, repairs)")
    parser.add_argument("--max-attempts", type=int, default=5,
                        help="with --repair: at most this many applied repairs (default 5)")
    parser.add_argument("--report", metavar="FILE.html",
                        help="write the run's HTML report: steps, failures, repairs, ground truth, top views, trees")
    parser.add_argument("--record-rrd", metavar="FILE.rrd",
                        help="record the episode for the Rerun viewer (needs the extra: pip install 'bt-meta[rerun]')")
    parser.add_argument("--record-mcap", metavar="FILE.mcap",
                        help="with --world ros2: record the run's ROS 2 messages as MCAP (docs/ros2.md)")
    add_world_arguments(parser)
    add_ros2_arguments(parser)
    add_memory_argument(parser)
    add_plugin_arguments(parser)
    add_groot2_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bt_meta.htn import load_task_file
    from bt_meta.world.simulation.sim_world import load_grounding, quiet_stdout

    if args.max_ticks < 1:
        raise UserInputError("--max-ticks must be at least 1")
    if args.max_attempts < 0:
        raise UserInputError("--max-attempts must be at least 0")
    check_groot2_arguments(args)
    if args.repair and args.btlog is not None:
        raise UserInputError("a .btlog file holds one tree; --repair replaces it as it repairs", "--repair")
    task_file = load_task_file(args.file)
    problem = task_file.problem(args.problem)  # unknown names list the known ones (exit 2)
    grounding = load_grounding(task_file.domain.name, args.file, args.grounding)
    grounding.problem(problem.name)
    options = world_options(args)
    make_world = world_factory(args)
    plugins = plugin_host_from_args(args, args.file)
    with _memory(args) as memory:
        recorder = None
        if args.record or args.record_failed:
            from bt_meta.memory.recorder import TraceRecorder

            recorder = TraceRecorder(memory, record_failed=args.record_failed, seed=args.seed,
                                     config={"command": "bt-meta run" + (" --repair" if args.repair else "")})
            plugins.register(recorder, "recorder", source="bt-meta run --record")
        page = capture = None
        if args.report:
            from bt_meta.runs.report import RunPage

            page = RunPage("bt-meta run")
            capture = page.capture
            plugins.register(capture, "run_report_capture", source="bt-meta run --report")
        started = time.perf_counter()
        with quiet_stdout():
            world = make_world(task_file.domain, problem, grounding, variant=args.variant, seed=args.seed, gui=args.gui,
                             **options)
        built = time.perf_counter()
        if page is not None:
            try:
                page.start(world)
            except BaseException:
                world.close()
                raise
        rrd = None
        if args.record_rrd:
            from bt_meta.world.simulation.rerun_log import RerunRecorder

            try:
                rrd = RerunRecorder(args.record_rrd, world)
            except BaseException:
                world.close()
                raise
            if args.repair:
                plugins.register(rrd, "rerun_recorder", source="bt-meta run --record-rrd")
        out: dict[str, Any] = {"file": str(args.file), "problem": problem.name, "variant": world.variant,
                               "scene": world.scene.name, "seed": args.seed, "robot": world.sim.robot.name,
                               "frames": world.sim.robot.frames()}  # every pose below is in the robot base frame
        if rrd is not None:
            out["rrd"] = str(rrd.path)
        tree_log = None
        if getattr(world, "recording", None) is not None:  # --record-mcap: what the tree did goes in too
            from bt_meta.ros2.mcap_recording import McapTreeLog

            tree_log = McapTreeLog(world.recording)
            plugins.register(tree_log, "mcap_tree_log", source="bt-meta run --record-mcap")
        try:
            if args.repair:
                code = _run_repaired(args, task_file, problem, world, plugins, memory, recorder, out, started, built,
                                     capture, tree_log)
            else:
                code = _run_plain(args, problem, world, plugins, memory, recorder, out, started, built, rrd, capture,
                                  tree_log, task_file)
            if page is not None:  # after the result is printed and recorded: a bad path loses none of it
                page.finish(args.file, task_file, problem, world, out, memory)
                written = page.write(args.report)
                if not args.json:
                    print(f"report: {written} ({page.verdict})")
            return code
        finally:
            if rrd is not None:
                rrd.close()
            world.close()


@contextlib.contextmanager
def _memory(args: argparse.Namespace) -> Iterator[Any]:
    """The run's episodic memory (or ``None``), with ``$BT_META_MEMORY`` pointing at it while the run lasts so
    plugins that open the memory themselves read the same file."""
    from bt_meta.memory import EpisodicMemory

    writes = args.record or args.record_failed or args.repair
    path = resolve_memory_path(args, writing=bool(writes))
    if writes:
        memory = EpisodicMemory.open(path)
        try:
            memory.require_sound()
        except BaseException:
            memory.close()
            raise
    elif args.memory:
        memory = EpisodicMemory.open(path, create=False, readonly=not os.access(path, os.W_OK))
    else:
        memory = None
    if memory is None:
        yield None
        return
    previous = os.environ.get(ENV_VAR)
    os.environ[ENV_VAR] = str(memory.path)
    try:
        yield memory
    finally:
        memory.close()
        if previous is None:
            os.environ.pop(ENV_VAR, None)
        else:
            os.environ[ENV_VAR] = previous


def _run_plain(args: argparse.Namespace, problem: Any, world: Any, plugins: Any, memory: Any, recorder: Any,
               out: dict[str, Any], started: float, built: float, rrd: Any = None, capture: Any = None,
               tree_log: Any = None, task_file: Any = None) -> int:
    from bt_meta.bt.failures import Failure, FailureKind
    from bt_meta.testing import TreeHarness

    try:
        harness = TreeHarness.from_file(args.file, problem.name, world=world, plugins=plugins)
    except PlanningError as error:
        failure = Failure(kind=FailureKind.PRECONDITION, message=str(error), evidence={"planner": str(error)})
        return _report(args, out, "FAILURE", 0, [failure.to_dict()], world, [], started, built, recorder, task_file)
    if memory is not None:
        harness.run.memory = memory  # what the grid-map and keypoint expectation plugins read
    if recorder is not None:
        recorder.tree = harness.compiled.plan_result.tree
    if tree_log is not None:
        tree_log.watch(harness.run)
    if capture is not None:  # one segment: the tree ticked here, with the statuses its step events report
        from bt_meta.runs.capture import Segment

        capture.segments.append(Segment(1, harness.root, 0))
    plan = [" ".join((p.name, *p.args)) for p in harness.compiled.plan_result.plan]
    if not args.json:
        print(f"{problem.name} in scene {world.scene.name} ({world.variant}), seed {args.seed}: "
              f"{len(plan)} primitives planned")
    shown = {b.name for b in harness.root.iterate() if shown_in_trace(b)}
    groot2 = start_groot2(args, harness)
    last: dict[str, str] = {}
    status = Status.RUNNING
    reported = 0
    while harness.run.tick_count < args.max_ticks:
        status = harness.tick()
        groot2.after_tick(status)
        seen = harness.statuses()
        nodes = {name: seen.get(f"Monitor<{name}>", value) for name, value in seen.items() if name in shown}
        changed = {name: value for name, value in nodes.items() if last.get(name) != value}
        last.update(nodes)
        new_failures = harness.failures[reported:]
        reported = len(harness.failures)
        if rrd is not None:
            rrd.log_tick(harness.run.tick_count, status.value, nodes, [f.summary() for f in new_failures])
        if not args.json and (changed or new_failures or status is not Status.RUNNING):
            listed = "  ".join(f"{name}={value}" for name, value in changed.items())
            print(f"tick {harness.run.tick_count:>4}  {status.value:<8} {listed}")
            for failure in new_failures:
                print(f"           failure {failure.summary()}")
        if status is not Status.RUNNING:
            break
    harness.run.finish(status)
    failures = [f.to_dict() for f in harness.failures]
    harness.close()
    code = _report(args, out, status.value, harness.run.tick_count, failures, world, plan, started, built, recorder,
                   task_file)
    groot2.finish()
    return code


def _run_repaired(args: argparse.Namespace, task_file: Any, problem: Any, world: Any, plugins: Any, memory: Any,
                  recorder: Any, out: dict[str, Any], started: float, built: float, capture: Any = None,
                  tree_log: Any = None) -> int:
    from bt_meta.meta.executor import MetaExecutor
    from bt_meta.meta.reasoner import Limits
    from bt_meta.meta.refinements import RefinementStore
    from bt_meta.runs.capture import CapturingExecutor

    groot2 = follow_groot2(args)
    # --report: the executor that also snapshots each segment's tree and the reasoner's decisions
    base: type[MetaExecutor] = MetaExecutor if capture is None else CapturingExecutor
    extra: dict[str, Any] = {} if capture is None else {"capture": capture}

    class Executor(base):  # type: ignore[valid-type,misc]
        """Hands the recorder every segment's decomposition tree (the parent tasks of repaired steps), Groot2
        every segment's behaviour tree, and the MCAP tree log every segment's run."""

        def _segment(self, run: Any, plan_state: Any, *rest: Any) -> Any:  # type: ignore[override]
            if recorder is not None:
                recorder.tree = plan_state.tree
            groot2.watch(run, rest[0] if rest else None)
            if tree_log is not None:
                tree_log.watch(run)
            return super()._segment(run, plan_state, *rest)

    if not args.json:
        print(f"{problem.name} in scene {world.scene.name} ({world.variant}), seed {args.seed}: "
              f"running with repairs (at most {args.max_attempts} attempts)")
        plugins.register(_Progress(), "run_progress", source="bt-meta run --repair")
    with RefinementStore.open(memory.path) as refinements:
        report = Executor(task_file.domain, problem, world, plugins, task_file=task_file, variant=world.variant,
                          memory=memory, refinements=refinements, limits=Limits(max_attempts=args.max_attempts,
                                                                 max_ticks=args.max_ticks), **extra).run()
    status = "SUCCESS" if report.ok else "FAILURE"
    if capture is not None:
        out["segments"] = report.to_dict().get("segments")
    out.update({
        "attempts": [a.to_dict() for a in report.attempts],
        "repairs": report.repairs,
        "refinement_saved": report.refinement_saved,
        "refinements_used": report.refinements_used,
        "stop_reason": report.stop_reason,
        "reported": report.reported,
        "initial_plan": [" ".join(step) for step in report.initial_plan],
        "repair_status": report.status,
        "refused": report.refused,
        "refinements_skipped": report.refinements_skipped,
        "refinements_demoted": report.refinements_demoted,
        "fallback": report.fallback,
        "expected": report.expected,
    })
    if not args.json:
        if report.refinements_used:
            print(f"learned refinements used: {', '.join(report.refinements_used)}")
        for skipped in report.refinements_skipped:
            print(f"learned refinement not used: {skipped['method']}: {skipped['reason']}")
        for passed in report.expected:
            print(f"  step {passed['step']}: the refinement's learning run met the same objection here; it goes on")
        if report.fallback:
            print(f"  learned plan failed on replay, demoted: {', '.join(report.fallback['refinements'])}; "
                  f"went on with {report.fallback.get('to') or 'it as it stands (' + report.fallback['why_not'] + ')'}")
        print(f"initial plan: {len(report.initial_plan)} primitives; {len(report.attempts)} repair attempt(s)")
        for attempt in report.attempts:
            proposal = attempt.proposal
            failure = attempt.failure
            call = f"{failure.get('action') or ''}{tuple(failure.get('args') or ())}"
            print(f"  attempt {attempt.number}: {attempt.kind} at step {attempt.step} {call} -> "
                  f"{proposal.get('action')} by {proposal.get('plugin')} (score {proposal.get('score', 0):.2f}): "
                  f"{attempt.change} [{attempt.outcome}]")
        for refused in report.refused:
            proposal = refused["proposal"]
            print(f"  refused: {proposal.get('action')} by {proposal.get('plugin')} at step {refused['step']}: "
                  f"{refused['reason']}")
        if report.stop_reason:
            print(f"  stopped: {report.stop_reason}")
        if report.refinement_saved:
            saved = report.refinement_saved
            print(f"refinement saved: {saved.get('method') or saved.get('reason') or saved}")
    plan = [" ".join(step) for step in report.plan]
    code = _report(args, out, status, report.ticks, report.failures, world, plan, started, built, recorder,
                   task_file)
    groot2.finish()
    return code


class _Progress:
    """Prints every finished step, failure and repair decision of a repaired run as it happens."""

    @hookimpl
    def bt_meta_trace_event(self, event: dict[str, Any]) -> None:
        kind = event.get("type")
        if kind == "step_end":
            call = f"{event.get('action')}({', '.join(str(a) for a in event.get('args') or ())})"
            print(f"tick {event.get('tick', 0):>4}  step {event.get('step')} {event.get('node_id') or ''} {call}"
                  f" {event.get('status')}")
        elif kind == "failure":
            failure = event.get("failure") or {}
            print(f"           failure [{failure.get('kind')}] {failure.get('message')}")
        elif kind == "repair":
            attempt = event.get("attempt") or {}
            proposal = attempt.get("proposal") or event.get("proposal") or {}
            what = f"{proposal.get('action')} by {proposal.get('plugin')}" if proposal else ""
            detail = attempt.get("change") or event.get("reason") or ""
            print(f"           repair {event.get('outcome')}: {what}{': ' if what and detail else ''}{detail}")


def _report(args: argparse.Namespace, out: dict[str, Any], status: str, ticks: int, failures: list[dict[str, Any]],
            world: Any, plan: list[str], started: float, built: float, recorder: Any = None,
            task_file: Any = None) -> int:
    finished = time.perf_counter()
    if recorder is not None:
        if recorder.error is not None:
            raise recorder.error
        out["episode_id"] = recorder.episode_id
        out["recording"] = ("stored" if recorder.episode_id is not None
                            else recorder.skipped or "the run never started (no plan)")
    observed = world.observe()
    if task_file is not None:  # the task's goal on the simulator's true state, as campaigns and the demo judge it
        from bt_meta.runs.report import judge_world

        out["achieved"], out["truth"] = judge_world(Path(args.file), task_file, task_file.problem(args.problem), world)
    keys = ("kind", "step", "node_id", "action", "args", "evidence", "message")
    out.update({
        "status": status,
        "ticks": ticks,
        "sim_steps": world.sim.steps,
        "build_seconds": round(built - started, 3),
        "run_seconds": round(finished - built, 3),
        "plan": plan,
        "failures": [{key: f.get(key) for key in keys} for f in failures],
        "objects": observed["objects"],
        "attachments": observed["attachments"],
        "held": observed["held"],
        "symbolic_state": [list(atom) for atom in sorted(world.symbolic_state())],
        "skills": world.executed,
    })
    if args.json:
        print_json(out)
    else:
        print(f"{status} after {ticks} ticks ({world.sim.steps} physics steps; built in {out['build_seconds']} s, "
              f"ran in {out['run_seconds']} s), {len(failures)} failure(s)")
        for failure in failures:
            print(f"  [{failure['kind']}] {failure.get('node_id') or ''} {failure.get('action') or ''}"
                  f"{tuple(failure.get('args') or ())}: {failure['message']}")
        if "achieved" in out:
            verdict = {True: "done", False: "NOT done", None: "not judged"}[out["achieved"]]
            print(f"  ground truth (simulator): task {verdict} -- {out['truth']}")
        robot = world.sim.robot
        if observed["objects"]:
            print(f"  object positions: base frame ({robot.base_frame}); "
                  f"scene frame = base - {list(robot.scene_offset)}")
        for name, state in observed["objects"].items():
            pose = ", ".join(f"{v:.3f}" for v in state["pose"][:3])
            scene = ", ".join(f"{v:.3f}" for v in robot.base_to_scene(state["pose"][:3]))
            print(f"  {name:<10} at ({pose}) base, ({scene}) scene"
                  + (f" held by {state['held_by']}" if state["held_by"] else "")
                  + (f" joined to {', '.join(state['attached_to'])}" if state["attached_to"] else ""))
        if recorder is not None:
            print(f"recorded episode {recorder.episode_id} in {Path(recorder.memory.path)}"
                  if recorder.episode_id is not None else f"not recorded: {out['recording']}")
    return 0 if status == "SUCCESS" else 1


__all__ = ["register", "run"]
