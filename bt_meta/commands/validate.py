"""``bt-meta validate FILE``: load and check a YAML task file without planning.

Offers:

* :func:`register` -- adds ``validate FILE``; prints ``FILE: ok (N primitives, M methods, K problems)`` or the
  error as ``path:line:column: message`` (exit 2)
"""

from __future__ import annotations

import argparse

from bt_meta.htn import load_task_file


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("validate", help="check a YAML task file (syntax, names, arities, variables)")
    parser.add_argument("file", help="YAML task file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    taskfile = load_task_file(args.file)
    domain = taskfile.domain
    print(f"{args.file}: ok ({len(domain.primitives)} primitives, {len(domain.methods)} methods, "
          f"{len(taskfile.problems)} problems)")
    return 0
