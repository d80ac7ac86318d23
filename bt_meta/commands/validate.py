"""``bt-meta validate FILE``: load and check a YAML task file without planning.

Offers:

* :func:`register` -- adds ``validate FILE [--problem P.hddl]`` (YAML, or HDDL imported on the fly); prints
  ``FILE: ok (N primitives, M methods, K problems)`` or the error as ``path:line:column: message`` (exit 2)
"""

from __future__ import annotations

import argparse

from bt_meta.htn.hddl.files import load_task_input


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("validate",
                                   help="check a YAML task file or HDDL files (syntax, names, arities, variables)")
    parser.add_argument("file", help="YAML task file, or an HDDL domain or problem file (.hddl)")
    parser.add_argument("--problem", help="with an HDDL domain: an HDDL problem file to check with it")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    taskfile, _ = load_task_input(args.file, args.problem)
    domain = taskfile.domain
    print(f"{args.file}: ok ({len(domain.primitives)} primitives, {len(domain.methods)} methods, "
          f"{len(taskfile.problems)} problems)")
    return 0
