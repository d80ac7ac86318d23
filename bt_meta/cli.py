"""The ``bt-meta`` command line.

Each subcommand lives in its own module under :mod:`bt_meta.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a callable taking the parsed arguments and
returning an exit status. Modules are discovered at start-up, so adding a command never touches this file.

Exit statuses: 0 success, 1 the command ran but the outcome was a failure (no plan, a failed run),
2 bad input (a file that does not load, a bad argument), printed as one ``path:line:column: message`` line and
never as a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

import bt_meta
from bt_meta import commands
from bt_meta.errors import BtMetaError, UserInputError

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """An argparse parser whose usage errors are one line and exit 2, like every other input error."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="bt-meta",
        description="Plan YAML task files into behaviour trees, run them on a simulated Baxter, and repair "
        "failures from an episodic memory of successful runs.",
    )
    parser.add_argument("--version", action="version", version=f"bt-meta {bt_meta.__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for module_info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{module_info.name}")
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        return int(args.func(args) or EXIT_OK)
    except UserInputError as error:
        print(error.location_message(), file=sys.stderr)
        return EXIT_USAGE
    except BtMetaError as error:
        print(f"bt-meta: {error}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print("bt-meta: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
