"""The ``bt-meta`` command line.

Each subcommand lives in its own module under :mod:`bt_meta.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a callable taking the parsed arguments and
returning an exit status. Modules are discovered at start-up, so adding a command never touches this file.

Exit statuses: 0 success, 1 the command ran but the outcome was a failure (no plan, a failed run),
2 bad input (a file that does not load, a bad argument, an unusable memory file), printed as one
``path:line:column: message`` line and never as a traceback; 130 after Ctrl-C and 143 after SIGTERM (one line,
``finally`` blocks run so memory files are closed). An unexpected exception -- a bug -- is one
``bt-meta: internal error: ...`` line with exit status 1; ``BT_META_TRACEBACK=1`` shows its traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import signal
import sys
import threading
from collections.abc import Sequence
from typing import Any

import bt_meta
from bt_meta import commands
from bt_meta.errors import BtMetaError, UserInputError

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C
EXIT_TERMINATED = 143  # 128 + SIGTERM
TRACEBACK_ENV = "BT_META_TRACEBACK"


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


class Terminated(BaseException):
    """SIGTERM arrived: unwinds the command like Ctrl-C does (``finally`` blocks run, files are closed)."""


def _on_sigterm(signum: int, frame: object) -> None:
    raise Terminated()


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; every way it can end is an exit status and at most one line on stderr."""
    previous = None
    try:
        previous = _install_sigterm()
        return _main(argv)
    except KeyboardInterrupt:
        _ignore_further(signal.SIGINT)  # a second Ctrl-C during the cleanup must not turn into a traceback
        print("bt-meta: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        _ignore_further(signal.SIGTERM)
        print("bt-meta: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _ignore_further(signum: int) -> None:
    if threading.current_thread() is threading.main_thread():
        with contextlib.suppress(ValueError, OSError):
            signal.signal(signum, signal.SIG_IGN)


def _install_sigterm() -> Any:
    if threading.current_thread() is not threading.main_thread():
        return None
    try:
        return signal.signal(signal.SIGTERM, _on_sigterm)
    except (ValueError, OSError):  # pragma: no cover - an embedding that forbids it
        return None


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        if getattr(args, "json", False):
            from bt_meta.commands._common import json_document_stdout

            with json_document_stdout():
                return int(args.func(args) or EXIT_OK)
        return int(args.func(args) or EXIT_OK)
    except UserInputError as error:
        print(_one_line(error.location_message()), file=sys.stderr)
        return EXIT_USAGE
    except BtMetaError as error:
        print(_one_line(f"bt-meta: {error}"), file=sys.stderr)
        return EXIT_FAILURE
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_OK
    except Exception as error:
        # A bug of bt-meta (or of a plugin outside a hook): one line, not a traceback, unless asked for.
        if os.environ.get(TRACEBACK_ENV):
            raise
        print(_one_line(f"bt-meta: internal error: {type(error).__name__}: {error} (set {TRACEBACK_ENV}=1 for the "
                        "traceback)"), file=sys.stderr)
        return EXIT_FAILURE


def _one_line(text: str) -> str:
    return " ".join(text.splitlines())


def _silence_stdout() -> None:
    """After a closed pipe, point stdout at /dev/null so the interpreter's final flush cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
