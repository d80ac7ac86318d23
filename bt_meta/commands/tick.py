"""``bt-meta tick FILE``: run a task file's plan (or a tree XML) tick by tick and print what every node did.

Offers:

* :func:`register` -- adds ``tick FILE [--problem P] [--task-file T] [--policy] [--world fake] [--ticks N]
  [--ticks-per-skill K] [--fault SPEC ...] [--seed N] [--world-option K=V ...] [--keep-ticking] [--plugins DIR]
  [--repair [--max-attempts N] [--memory PATH]] [--json] [--groot2 [PORT]] [--groot2-host ADDRESS] [--hold]
  [--btlog FILE] [--tick-period MS]`` and, for tree XML, ``[--tree ID] [--include-path DIR] [--subtrees PATH]
  [--stub-unknown] [--stub ...] [--ros2-leaves FILE.yaml]``

FILE is a YAML task file (planned, then compiled) or a tree XML (its primitives come from ``--task-file``, by default
the ``.yaml`` next to it). Ticking stops when the root finishes unless ``--keep-ticking``. ``--tick-period MS``
waits that long between ticks while the root is RUNNING (BT.CPP's ``tickWhileRunning``); by default 10 ms when the
tree has leaves whose result comes from another process (ROS leaves), else none. Each tick prints the root
status and the status of every primitive and guard ticked; failures are printed with kind, node and evidence.
Exit status 0 when the root succeeded or is still running, 1 when it failed, 2 on bad input.

``--repair`` (task files only) runs the problem through the
:class:`~bt_meta.meta.executor.MetaExecutor` on the chosen world instead: every failure (e.g. one injected with
``--fault``) is classified, the repair plugins propose fixes, the best one is applied and the run goes on, at most
``--max-attempts`` times. It prints one line per finished step, failure and repair decision, then the outcome
(JSON: ``status``, ``attempts``, ``repairs``, ``stop_reason``, ``plan``, ``initial_plan``, ``failures``). A
``--memory`` file gives the repairs their episodic memory and keeps learned refinements; without it the run uses
none and saves none.

``--groot2``/``--btlog``: the run is visible live in Groot2 and/or logged for its replay (see docs/groot2.md).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

from py_trees.common import Status

from bt_meta.commands._common import print_json, shown_in_trace
from bt_meta.commands._groot2_args import add_groot2_arguments, check_groot2_arguments, start_groot2
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.commands._tree_args import (
    add_tree_arguments,
    ros2_leaves_from_args,
    stubs_from_args,
    tree_sources_from_args,
)
from bt_meta.errors import UserInputError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("tick", help="tick a plan or tree XML in a world and print statuses per tick")
    parser.add_argument("file", help="YAML task file or BehaviorTree.CPP v4 XML")
    parser.add_argument("--problem", help="problem name (required when the file has several)")
    parser.add_argument("--task-file", help="for a tree XML: the task file with its domain and problem")
    parser.add_argument("--policy", action="store_true", help="tick the policy tree instead of a plan")
    parser.add_argument("--world", default="fake", help="world to act on (default: fake; plugins add others)")
    parser.add_argument("--ticks", type=int, default=100, help="at most this many ticks (default 100)")
    parser.add_argument("--ticks-per-skill", type=int, default=1, help="fake world: ticks each skill takes (1)")
    parser.add_argument("--fault", action="append", default=[], metavar="SPEC",
                        help="fake world fault ACTION[(ARGS)][#N]=fail[:KIND]|silent|raise (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="seed for worlds that draw random numbers (0)")
    parser.add_argument("--world-option", action="append", default=[], metavar="KEY=VALUE",
                        help="extra option for the world plugin, e.g. variant=rotated (repeatable)")
    parser.add_argument("--keep-ticking", action="store_true", help="keep ticking after the root finished")
    parser.add_argument("--tick-period", type=float, default=None, metavar="MS",
                        help="wait this long between ticks while the root is RUNNING (default: 10 when the tree "
                             "has ROS leaves, else 0)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with every tick")
    parser.add_argument("--repair", action="store_true",
                        help="task files: diagnose and repair failures with the meta-reasoner while ticking")
    parser.add_argument("--max-attempts", type=int, default=5,
                        help="with --repair: at most this many applied repairs (default 5)")
    parser.add_argument("--memory", help="with --repair: episodic memory file (SQLite) for the repairs")
    add_plugin_arguments(parser)
    add_groot2_arguments(parser)
    add_tree_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bt_meta.testing import TreeHarness
    from bt_meta.world.fake import Fault

    if args.ticks < 1:
        raise UserInputError("--ticks must be at least 1")
    if args.ticks_per_skill < 1:
        raise UserInputError("--ticks-per-skill must be at least 1")
    check_groot2_arguments(args)
    faults = [Fault.parse(spec) for spec in args.fault]
    world_options: dict[str, Any] = {"seed": args.seed}
    for item in args.world_option:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UserInputError(f"bad --world-option {item!r}: expected KEY=VALUE")
        world_options[key.strip()] = value.strip()
    from bt_meta.bt.loading import is_xml

    if not is_xml(args.file) and (args.tree or args.include_path or args.subtrees or args.stub_unknown):
        raise UserInputError("--tree, --include-path, --subtrees and --stub-unknown apply to tree XML", args.file)
    if args.tick_period is not None and args.tick_period < 0:
        raise UserInputError("--tick-period must be at least 0")
    if args.ros2_leaves and not is_xml(args.file):
        raise UserInputError("--ros2-leaves registers leaves of a tree XML", args.file)
    ros2_leaves_from_args(args, register=True)
    plugins = plugin_host_from_args(args, args.file)
    if args.repair:
        if args.groot2 is not None or args.btlog is not None:
            raise UserInputError("--groot2 and --btlog watch one tree; with --repair use "
                                 "'bt-meta run --repair --groot2' (the simulator) instead")
        return _run_repaired(args, faults, world_options, plugins)
    harness = TreeHarness.from_file(args.file, args.problem, task_file=args.task_file, policy=args.policy,
                                    world=args.world, faults=faults, ticks_per_skill=args.ticks_per_skill,
                                    world_options=world_options, plugins=plugins, tree_id=args.tree,
                                    xml_sources=tree_sources_from_args(args), stubs=stubs_from_args(args))
    shown = {b.name for b in harness.root.iterate() if shown_in_trace(b)}
    period = args.tick_period
    if period is None:  # BT.CPP's tickWhileRunning sleeps 10 ms; a tree of local leaves needs no wait
        period = 10.0 if any(getattr(b, "waits_on_outside", False) for b in harness.root.iterate()) else 0.0
    groot2 = start_groot2(args, harness)
    ticks: list[dict[str, Any]] = []
    status = Status.INVALID
    reported = 0
    for _ in range(args.ticks):
        status = harness.tick()
        groot2.after_tick(status)
        # Show a monitored action with its monitor's verdict (what the tree saw).
        seen = harness.statuses()
        nodes = {name: seen.get(f"Monitor<{name}>", value) for name, value in seen.items() if name in shown}
        new_failures = harness.failures[reported:]
        reported = len(harness.failures)
        ticks.append({"tick": harness.run.tick_count, "status": status.value, "nodes": nodes,
                      "failures": [f.to_dict() for f in new_failures]})
        if not args.json:
            listed = "  ".join(f"{name}={value}" for name, value in nodes.items())
            print(f"tick {harness.run.tick_count:>3}  {status.value:<8} {listed}")
            for failure in new_failures:
                print(f"          failure {failure.summary()}")
        if status is not Status.RUNNING and not args.keep_ticking:
            break
        if period > 0:
            time.sleep(period / 1000.0)
    harness.run.finish(status)
    final_state = sorted(" ".join(a) for a in harness.state)
    if args.json:
        print_json({
            "file": str(args.file),
            "problem": None if harness.compiled.problem is None else harness.compiled.problem.name,
            "world": args.world,
            "mode": harness.compiled.mode,
            "status": status.value,
            "ticks": ticks,
            "failures": [f.to_dict() for f in harness.failures],
            "state": [list(a) for a in sorted(harness.state)],
        })
    else:
        print(f"{status.value} after {harness.run.tick_count} ticks, {len(harness.failures)} failures; "
              f"belief state: {len(final_state)} atoms")
    groot2.finish()
    harness.close()
    return 1 if status is Status.FAILURE else 0


def _run_repaired(args: argparse.Namespace, faults: list[Any], world_options: dict[str, Any], plugins: Any) -> int:
    from bt_meta.commands.run import _Progress
    from bt_meta.errors import PluginError
    from bt_meta.htn import load_task_file
    from bt_meta.meta.executor import MetaExecutor
    from bt_meta.meta.reasoner import Limits

    if args.max_attempts < 0:
        raise UserInputError("--max-attempts must be at least 0")
    if args.policy or not str(args.file).endswith((".yaml", ".yml")):
        raise UserInputError("--repair needs a YAML task file (it replans from the task file's methods)", args.file)
    task_file = load_task_file(args.file)
    problem = task_file.problem(args.problem)
    options = {"faults": faults, "ticks_per_skill": args.ticks_per_skill, "task_file": str(args.file),
               **world_options}
    made = plugins.call("bt_meta_make_world", name=args.world, domain=task_file.domain, problem=problem,
                        options=options)
    if made.errors:
        error = made.errors[0]
        raise error.error if isinstance(error.error, UserInputError) else PluginError(error.message)
    if not made.results:
        raise UserInputError(f"no plugin provides a world named {args.world!r}")
    world = made.first
    if not args.json:
        print(f"{problem.name} on the {args.world} world: ticking with repairs (at most {args.max_attempts} attempts)")
        plugins.register(_Progress(), "tick_progress", source="bt-meta tick --repair")
    memory = refinements = None
    try:
        if args.memory:
            from bt_meta.memory import EpisodicMemory
            from bt_meta.meta.refinements import RefinementStore

            memory = EpisodicMemory.open(args.memory)
            refinements = RefinementStore.open(memory.path)
        report = MetaExecutor(task_file.domain, problem, world, plugins, task_file=task_file, memory=memory,
                              refinements=refinements, save_refinements=refinements is not None,
                              limits=Limits(max_attempts=args.max_attempts, max_ticks=args.ticks)).run()
    finally:
        if refinements is not None:
            refinements.close()
        if memory is not None:
            memory.close()
        close = getattr(world, "close", None)
        if callable(close):
            close()
    status = "SUCCESS" if report.ok else "FAILURE"
    if args.json:
        print_json({
            "file": str(args.file), "problem": problem.name, "world": args.world, "status": status,
            "ticks": report.ticks, "attempts": [a.to_dict() for a in report.attempts], "repairs": report.repairs,
            "stop_reason": report.stop_reason, "plan": [" ".join(step) for step in report.plan],
            "initial_plan": [" ".join(step) for step in report.initial_plan], "failures": report.failures,
        })
    else:
        for attempt in report.attempts:
            proposal = attempt.proposal
            print(f"  attempt {attempt.number}: {attempt.kind} at step {attempt.step} -> {proposal.get('action')} "
                  f"by {proposal.get('plugin')}: {attempt.change} [{attempt.outcome}]")
        if report.stop_reason:
            print(f"  stopped: {report.stop_reason}")
        print(f"{status} after {report.ticks} ticks, {len(report.attempts)} repair attempt(s); "
              f"plan: {'; '.join(' '.join(step) for step in report.plan)}")
    return 0 if report.ok else 1
