"""``bt-meta compile FILE``: plan a task file's problem and write the monitored behaviour tree as BT.CPP v4 XML.

Offers:

* :func:`register` -- adds ``compile FILE [--problem P] [--policy] [--depth N] [-o tree.xml] [--tree ID]
  [--plugins DIR]``

Monitors are implicit in the XML (the loader adds them back around every primitive). Exit status 0 when written,
1 when the planner finds no plan, 2 on bad input.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.errors import UserInputError
from bt_meta.user_files import check_output_file, describe_os_error


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("compile", help="compile a task file's plan (or policy) to BT.CPP v4 XML")
    parser.add_argument("file", help="YAML task file, or an HDDL domain or problem file (.hddl)")
    parser.add_argument("--problem", help="problem name (required when the file has several); with an HDDL "
                                          "domain, the HDDL problem file")
    parser.add_argument("--policy", action="store_true",
                        help="compile the whole method library as a reactive policy tree instead of one plan")
    parser.add_argument("--depth", type=int, default=None, help="with --policy: how deep recursive tasks expand")
    parser.add_argument("-o", "--output", help="write the XML here (default: stdout)")
    parser.add_argument("--tree", metavar="ID", help="the <BehaviorTree ID> of the written tree (default: "
                        "Plan_<problem> or Policy_<problem>)")
    add_plugin_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bt_meta.bt.compiler import DEFAULT_POLICY_DEPTH, compile_task_file
    from bt_meta.bt.loading import is_xml
    from bt_meta.bt.xml import tree_to_xml

    if is_xml(args.file):
        raise UserInputError("compile takes a YAML task file; a tree XML is already compiled", args.file)
    if args.depth is not None and args.depth < 1:
        raise UserInputError("--depth must be at least 1")
    if args.output:
        check_output_file(args.output, "output file (-o)")  # before the work, not after it
    from bt_meta.htn.hddl.files import load_task_input

    plugins = plugin_host_from_args(args, args.file)
    task_file, problem_name = load_task_input(args.file, args.problem)
    compiled = compile_task_file(task_file, problem_name, policy=args.policy, plugins=plugins,
                                 max_depth=args.depth or DEFAULT_POLICY_DEPTH)
    if args.tree is not None and not re.match(r"^[A-Za-z_][A-Za-z0-9_.\-]*$", args.tree):
        raise UserInputError(f"--tree {args.tree!r} is not a valid tree ID")
    default_id = f"{'Policy' if args.policy else 'Plan'}_{compiled.problem.name}"
    tree_id = args.tree or re.sub(r"[^A-Za-z0-9_]", "_", default_id)
    text = tree_to_xml(compiled.root, tree_id=tree_id, registry=compiled.registry)
    if args.output:
        try:
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as error:
            raise UserInputError(f"cannot write the output file (-o): {describe_os_error(error)}",
                                 args.output) from None
        count = compiled.stats.get("primitives")
        what = f"{count} primitives" if count is not None else "policy tree"
        print(f"wrote {args.output} ({what}, tree {tree_id})", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
