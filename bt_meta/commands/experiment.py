"""``bt-meta experiment NAME``: the paper's experiments reproduced in simulation (one module of
:mod:`bt_meta.experiments` each, discovered like the benchmarks)."""

from __future__ import annotations

import argparse

from bt_meta import experiments
from bt_meta.commands._common import register_modules


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("experiment", help="run one of the paper's experiments in simulation")
    experiment_subparsers = parser.add_subparsers(dest="experiment", metavar="NAME", parser_class=type(parser))
    register_modules(experiments, experiment_subparsers)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)
