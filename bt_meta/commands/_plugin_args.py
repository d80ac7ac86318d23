"""Command-line options shared by the commands that load plugins (``--plugins DIR``, ``--no-entry-points``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_plugin_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--plugins", action="append", default=[], metavar="DIR",
                        help="also load every plugin file in DIR (repeatable); the project's own plugins/ folder "
                             "next to FILE is always loaded")
    parser.add_argument("--no-entry-points", action="store_true",
                        help="do not load installed plugins (the bt_meta entry-point group)")
    parser.add_argument("--hook-budget", metavar="SECONDS", default=None,
                        help="time budget of each plugin hook call; a call past it is an internal failure "
                             "(default: $BT_META_HOOK_BUDGET, else 60; 0 for none)")


def plugin_host_from_args(args: argparse.Namespace, project_file: str | Path | None) -> Any:
    from bt_meta.hook_budget import parse_budget
    from bt_meta.plugins import FROM_ENVIRONMENT, create_plugin_host

    given = getattr(args, "hook_budget", None)
    budget = FROM_ENVIRONMENT if given is None else parse_budget(given, "--hook-budget")
    return create_plugin_host(args.plugins, project_file=project_file, entry_points=not args.no_entry_points,
                              hook_budget=budget)
