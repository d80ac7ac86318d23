"""``bt-meta tick FILE``: run a task file's plan (or a tree XML) tick by tick and print what every node did.

Offers:

* :func:`register` -- adds ``tick FILE [--problem P] [--task-file T] [--policy] [--world fake] [--ticks N]
  [--ticks-per-skill K] [--fault SPEC ...] [--seed N] [--world-option K=V ...] [--keep-ticking] [--plugins DIR]
  [--json]`` and, for tree XML, ``[--tree ID] [--include-path DIR] [--subtrees PATH] [--stub-unknown] [--stub ...]``

FILE is a YAML task file (planned, then compiled) or a tree XML (its primitives come from ``--task-file``, by default
the ``.yaml`` next to it). Ticking stops when the root finishes unless ``--keep-ticking``. Each tick prints the root
status and the status of every primitive and guard ticked; failures are printed with kind, node and evidence.
Exit status 0 when the root succeeded or is still running, 1 when it failed, 2 on bad input.
"""

from __future__ import annotations

import argparse
from typing import Any

from py_trees.common import Status

from bt_meta.commands._common import print_json, shown_in_trace
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.commands._tree_args import add_tree_arguments, stubs_from_args, tree_sources_from_args
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
    parser.add_argument("--json", action="store_true", help="print one JSON object with every tick")
    add_plugin_arguments(parser)
    add_tree_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bt_meta.testing import TreeHarness
    from bt_meta.world.fake import Fault

    if args.ticks < 1:
        raise UserInputError("--ticks must be at least 1")
    if args.ticks_per_skill < 1:
        raise UserInputError("--ticks-per-skill must be at least 1")
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
    plugins = plugin_host_from_args(args, args.file)
    harness = TreeHarness.from_file(args.file, args.problem, task_file=args.task_file, policy=args.policy,
                                    world=args.world, faults=faults, ticks_per_skill=args.ticks_per_skill,
                                    world_options=world_options, plugins=plugins, tree_id=args.tree,
                                    xml_sources=tree_sources_from_args(args), stubs=stubs_from_args(args))
    shown = {b.name for b in harness.root.iterate() if shown_in_trace(b)}
    ticks: list[dict[str, Any]] = []
    status = Status.INVALID
    reported = 0
    for _ in range(args.ticks):
        status = harness.tick()
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
    harness.close()
    return 1 if status is Status.FAILURE else 0
