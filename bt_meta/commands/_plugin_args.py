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


def plugin_host_from_args(args: argparse.Namespace, project_file: str | Path | None) -> Any:
    from bt_meta.plugins import create_plugin_host

    return create_plugin_host(args.plugins, project_file=project_file, entry_points=not args.no_entry_points)
