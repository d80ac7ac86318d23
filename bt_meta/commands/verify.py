"""``bt-meta verify FILE [--problem P] PLAN.json``: check a plan and its decomposition tree independently.

Offers:

* :func:`register` -- adds ``verify FILE [--problem P] PLAN.json [--json]``

``FILE`` is a YAML task file (``--problem`` a problem name) or HDDL (a domain with ``--problem p.hddl``, or a
problem file). ``PLAN.json`` is what ``bt-meta plan --json`` prints. The check (:mod:`bt_meta.htn.verify`)
follows PANDA's plan verifier: the plan is executable, the goal holds, the tree decomposes the task network.
Exit status 0 when verified, 1 when the plan is invalid (each problem printed), 2 on input that does not load.
"""

from __future__ import annotations

import argparse

from bt_meta.commands._common import print_json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("verify", help="check a plan (and its decomposition tree) against a problem")
    parser.add_argument("file", help="YAML task file, or an HDDL domain or problem file (.hddl)")
    parser.add_argument("plan", help="plan JSON, as bt-meta plan --json prints it")
    parser.add_argument("--problem", help="problem name; with an HDDL domain, the HDDL problem file")
    parser.add_argument("--json", action="store_true", help='print {"ok", "errors", "steps", "nodes"}')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bt_meta.htn.hddl.files import load_task_input
    from bt_meta.htn.verify import read_plan_json, verify_plan

    taskfile, problem_name = load_task_input(args.file, args.problem)
    problem = taskfile.problem(problem_name)
    steps, tree = read_plan_json(args.plan)
    verdict = verify_plan(taskfile.domain, problem, steps, tree)
    if args.json:
        print_json({"ok": verdict.ok, "errors": verdict.errors, "steps": verdict.steps, "nodes": verdict.nodes})
    else:
        print(f"{args.plan}: problem {problem.name}: {verdict.summary() if verdict.ok else 'plan INVALID'}")
        for error in verdict.errors:
            print(f"  {error}")
    return 0 if verdict.ok else 1
