"""``bt-meta import hddl DOMAIN.hddl [PROBLEM.hddl ...] [-o FILE.yaml] [--map MAP.json]``: HDDL to a task file.

Offers:

* :func:`register` -- adds ``import`` with the ``hddl`` format (the module is not named ``import``, a keyword)

The written file loads with the ordinary loader (it is checked before it is written) and keeps every HDDL name
the task-file syntax can spell; ``--map`` writes ``{"names": {task-file name: HDDL name}, "synthetic": {...}}``
for the others and for the names the importer made up (auxiliary axioms, root tasks). Exit status 0 when
written, 2 on HDDL that does not parse or cannot be imported (``path:line:column: message``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("import", help="convert planning files of another format into a task file")
    formats = parser.add_subparsers(dest="format", metavar="FORMAT", parser_class=type(parser))
    hddl = formats.add_parser("hddl", help="HDDL domain (+ problems) to a YAML task file")
    hddl.add_argument("domain", help="HDDL domain file")
    hddl.add_argument("problems", nargs="*", help="HDDL problem files")
    hddl.add_argument("-o", "--output", help="write the task file here (default: stdout)")
    hddl.add_argument("--map", dest="map_file", help="write the renamed and made-up names here as JSON")
    hddl.set_defaults(func=run_hddl)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)


def run_hddl(args: argparse.Namespace) -> int:
    from bt_meta.htn.hddl import import_hddl
    from bt_meta.htn.loader import load_task_text

    converted = import_hddl(args.domain, args.problems)
    base = Path(args.output).resolve().parent if args.output else Path.cwd()
    load_task_text(converted.text, f"{args.domain} (imported)", base_dir=base)  # it must load as written
    if args.output:
        Path(args.output).write_text(converted.text, encoding="utf-8")
        print(f"wrote {args.output} ({len(converted.problems)} problem(s), {len(converted.names)} renamed "
              f"name(s))", file=sys.stderr)
    else:
        sys.stdout.write(converted.text)
    if args.map_file:
        Path(args.map_file).write_text(converted.map_json(), encoding="utf-8")
    return 0
