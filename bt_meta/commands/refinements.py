"""``bt-meta refinements ls | export``: the method refinements learned from repaired runs.

Offers:

* ``bt-meta refinements ls [--domain D] [--json]`` -- the stored refinements, newest first (the order they are
  tried in): task, method, precondition (the starting poses), the repaired plan, the perceived facts it adds and
  the goal as the repair rewrote it (when it has them), and the repair it came from
* ``bt-meta refinements export [TASK_FILE] [--domain D] [-o FILE]`` -- a task file (YAML, the ``bt-meta plan``
  format) of the domain with its refinements as its first methods, plus the problems of ``TASK_FILE``. Without
  ``TASK_FILE`` the domain's file recorded with the refinements is used.

Both take ``--memory PATH`` (else ``$BT_META_MEMORY``, else ``./.bt-meta/memory.sqlite``); reading never creates a
memory file. Planning with an exported file needs the ``pose_within`` plugin (``bt_meta_plugins.
refinement_predicates``) and a world that reports object poses; elsewhere the refinements simply do not apply.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from bt_meta.commands._common import print_json
from bt_meta.errors import UserInputError
from bt_meta.htn.state import atom_text
from bt_meta.memory import add_memory_argument, resolve_memory_path
from bt_meta.meta.refinements import Refinement, RefinementStore


class RefinementsInputError(UserInputError):
    """An export that cannot be written as asked (which domain, which file)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("refinements", help="learned method refinements (ls, export)")
    actions = parser.add_subparsers(dest="refinements_command", metavar="ACTION", parser_class=type(parser))

    ls = actions.add_parser("ls", help="list the stored refinements, newest first")
    ls.add_argument("--domain", metavar="D", help="only refinements of this domain")
    ls.add_argument("--json", action="store_true", help="print JSON")
    add_memory_argument(ls)
    ls.set_defaults(func=_ls)

    export = actions.add_parser("export", help="write the domain with its refinements as a task file (YAML)")
    export.add_argument("task_file", metavar="TASK_FILE", nargs="?",
                        help="task file of the domain (default: the one recorded with the refinements)")
    export.add_argument("--domain", metavar="D", help="which domain, when the memory has refinements of several")
    export.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of standard output")
    add_memory_argument(export)
    export.set_defaults(func=_export)
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])


def _open(args: argparse.Namespace) -> RefinementStore:
    path = resolve_memory_path(args)
    readonly = path.exists() and not os.access(path, os.W_OK)
    return RefinementStore.open(path, create=False, readonly=readonly)


def _ls(args: argparse.Namespace) -> int:
    with _open(args) as store:
        refinements = store.list(domain=args.domain)
        if args.json:
            print_json([r.to_dict() for r in refinements])
            return 0
        if not refinements:
            print(f"no refinements{' of domain ' + args.domain if args.domain else ''} in {store.path}")
            return 0
        for refinement in refinements:
            _print(refinement)
    return 0


def _print(refinement: Refinement) -> None:
    repair = refinement.repair or {}
    print(f"{refinement.id}  {refinement.domain}  {refinement.task}  ->  {refinement.method}  "
          f"({refinement.created}; problem {refinement.problem or '-'}; variant {refinement.variant or '-'})")
    status = refinement.status + (f" ({refinement.status_reason})" if refinement.status_reason else "")
    print(f"    robot {refinement.robot or 'unknown'}; {status}; replayed {refinement.replays} time(s), "
          f"failed {refinement.failures}")
    print(f"    precondition: {refinement.precondition}")
    print(f"    plan: {', '.join(refinement.subtasks)}")
    add, delete = refinement.fact_atoms()
    if add or delete:
        parts = [f"{label} {', '.join(atom_text(a) for a in atoms)}"
                 for label, atoms in (("add", add), ("delete", delete)) if atoms]
        print(f"    perceived facts: {'; '.join(parts)}")
    goal = refinement.goal_atoms()
    if goal is not None:
        print(f"    goal (rewritten): {', '.join(atom_text(g) for g in goal) or '(empty)'}")
    changes = "; ".join(f"{p.get('action')} by {p.get('plugin')}: {p.get('change')}"
                        for p in repair.get("proposals", []))
    print(f"    learned from {repair.get('attempts', '?')} repair attempt(s): {changes or '-'}")


def _export(args: argparse.Namespace) -> int:
    from bt_meta.htn import load_task_file

    with _open(args) as store:
        refinements = store.list(domain=args.domain)
        if args.task_file is not None:
            task_file = load_task_file(args.task_file)
        else:
            domains = sorted({r.domain for r in refinements})
            if not domains:
                raise RefinementsInputError(f"no refinements to export in {store.path}")
            if len(domains) > 1:
                raise RefinementsInputError(f"refinements of several domains ({', '.join(domains)}): choose one "
                                            "with --domain")
            source = next((r.domain_path for r in refinements if r.domain_path), None)
            if source is None or not Path(source).is_file():
                raise RefinementsInputError(f"the task file of domain {domains[0]} is unknown or gone "
                                            f"({source or 'not recorded'}): pass TASK_FILE")
            task_file = load_task_file(source)
        domain = task_file.domain
        if not any(r.domain == domain.name for r in refinements):
            print(f"bt-meta: note: no refinements of domain {domain.name} in {store.path}", file=sys.stderr)
        text = store.export_yaml(domain, task_file.problems.values())
    if args.output:
        try:
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as error:
            raise RefinementsInputError(f"cannot write: {error.strerror}", args.output) from None
    else:
        sys.stdout.write(text)
    return 0
