"""``bt-meta bench NAME``: benchmarks that print a ratio against a baseline measured in the same run."""

from __future__ import annotations

import argparse

from bt_meta import bench
from bt_meta.commands._common import register_modules


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("bench", help="run a benchmark against its baseline")
    bench_subparsers = parser.add_subparsers(dest="benchmark", metavar="NAME", parser_class=type(parser))
    register_modules(bench, bench_subparsers)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)
