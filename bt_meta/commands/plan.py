"""``bt-meta plan FILE``: plan a problem of a task file and print the plan and its decomposition tree.

Offers:

``FILE`` may be HDDL: ``plan domain.hddl --problem p01.hddl`` or ``plan p01.hddl`` (its domain file found beside
it, see :func:`bt_meta.htn.hddl.find_domain_file`).

* :func:`register` -- adds ``plan FILE [--problem NAME] [--json] [--states] [--max-nodes N] [--max-seconds S]
  [--plugins DIR] [--no-entry-points]``

A domain that declares external predicates asks the loaded plugins for their truth at plan time (the
``bt_meta_external_predicate`` hook); a predicate no plugin answers ends the command with exit status 1.

Unless ``--max-nodes`` / ``--max-seconds`` say otherwise a plan gets the budget of :mod:`bt_meta.htn.budgets`
(10,000,000 expansions, 10 seconds).

Exit status 0 with a plan, 1 when there is no plan or the budget ran out (with the reason), 2 on a file that
does not load or a missing/unknown ``--problem``.
"""

from __future__ import annotations

import argparse
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.errors import UserInputError
from bt_meta.htn import plan
from bt_meta.htn.budgets import DEFAULT_MAX_NODES, DEFAULT_MAX_SECONDS
from bt_meta.htn.hddl.files import load_task_input


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("plan", help="plan a problem of a YAML task file (plan + decomposition tree)")
    parser.add_argument("file", help="YAML task file, or an HDDL domain or problem file (.hddl)")
    parser.add_argument("--problem", help="problem name (required when the file has several); with an HDDL "
                                          "domain, the HDDL problem file")
    parser.add_argument("--json", action="store_true", help="print one JSON object: plan, tree, stats")
    parser.add_argument("--states", action="store_true", help="with --json: include each node's state_before")
    parser.add_argument("--max-nodes", type=int, default=DEFAULT_MAX_NODES,
                        help=f"node budget in task expansions (default {DEFAULT_MAX_NODES:,})")
    parser.add_argument("--max-seconds", type=float, default=DEFAULT_MAX_SECONDS,
                        help=f"time budget in seconds (default {DEFAULT_MAX_SECONDS:g})")
    add_plugin_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.max_nodes is not None and args.max_nodes < 1:
        raise UserInputError("--max-nodes must be at least 1")
    if args.max_seconds is not None and args.max_seconds <= 0:
        raise UserInputError("--max-seconds must be positive")
    taskfile, problem_name = load_task_input(args.file, args.problem)
    problem = taskfile.problem(problem_name)
    external = None
    if taskfile.domain.external:  # only then are plugins needed: loading them costs more than most plans
        external = plugin_host_from_args(args, args.file).external_predicate
    result = plan(taskfile.domain, problem, max_nodes=args.max_nodes, max_seconds=args.max_seconds,
                  external=external)
    if args.json:
        payload: dict[str, Any] = {
            "file": str(args.file),
            "problem": problem.name,
            "status": result.status,
            "message": result.message,
            "plan": [action.as_list() for action in result.plan],
            "tree": result.tree.to_dict(states=args.states) if result.tree is not None else None,
            "stats": result.stats,
        }
        print_json(payload)
    else:
        print(f"{args.file}: problem {problem.name}: {result.message}")
        if result.ok:
            print("plan:")
            for index, action in enumerate(result.plan):
                print(f"  {index:>3}  {action}")
            print("decomposition tree:")
            assert result.tree is not None
            for line in result.tree.pretty().splitlines():
                print(f"  {line}")
    return 0 if result.ok else 1
