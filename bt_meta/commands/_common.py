"""Helpers shared by the subcommands: JSON output, the discovery of sub-subcommands, the nodes a trace shows."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import pkgutil
import sys
from collections.abc import Iterator
from types import ModuleType
from typing import Any, TextIO

from bt_meta._stdio import flush_c_stdio

_json_stream: TextIO | None = None
"""Where a ``--json`` command's document goes while :func:`json_document_stdout` holds stdout for it."""


def print_json(payload: Any) -> None:
    """Print one JSON document to stdout, the shape every ``--json`` flag promises."""
    out = json_stream()
    json.dump(payload, out, indent=2, sort_keys=False, default=str)
    out.write("\n")


def json_stream() -> TextIO:
    """The stream a ``--json`` document is written to: the real stdout, even while other output is diverted."""
    return _json_stream or sys.stdout


@contextlib.contextmanager
def json_document_stdout() -> Iterator[None]:
    """While a ``--json`` command runs, stdout carries its JSON document alone.

    What the engines print meanwhile goes to stderr: pybullet's C code (URDF warnings on file descriptor 1), Ray's
    driver (a lost node's raylet log on ``sys.stdout``). The document is written through :func:`json_stream`.
    """
    global _json_stream
    real = sys.stdout
    try:
        fd = real.fileno()
    except (AttributeError, OSError, ValueError):  # stdout is no file (captured): divert Python's output only
        _json_stream = real
        try:
            with contextlib.redirect_stdout(sys.stderr):
                yield
        finally:
            _json_stream = None
        return
    real.flush()
    saved = os.dup(fd)
    _json_stream = os.fdopen(saved, "w", encoding=getattr(real, "encoding", None) or "utf-8")
    try:
        sys.stderr.flush()
        os.dup2(sys.stderr.fileno(), fd)
        yield
    finally:
        stream, _json_stream = _json_stream, None
        with contextlib.suppress(OSError, ValueError):
            real.flush()
            flush_c_stdio()
        os.dup2(saved, fd)
        with contextlib.suppress(OSError, ValueError):  # a closed pipe: the CLI reports it
            stream.close()


def register_modules(package: ModuleType, subparsers: argparse._SubParsersAction) -> None:
    """Call ``register(subparsers)`` of every public module of ``package`` (for ``bench`` and friends)."""
    for module_info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{package.__name__}.{module_info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(subparsers)


def shown_in_trace(behaviour: Any) -> bool:
    """Whether ``run`` and ``tick`` print a node's status changes: the plan's primitives and their guards, and
    leaves that ask to be shown (``shown_in_trace = True``, e.g. ROS leaves)."""
    from bt_meta.bt.actions import PrimitiveAction
    from bt_meta.bt.guards import CheckCondition

    return isinstance(behaviour, (PrimitiveAction, CheckCondition)) or getattr(behaviour, "shown_in_trace", False) \
        is True
