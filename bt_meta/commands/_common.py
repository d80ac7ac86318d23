"""Helpers shared by the subcommands: JSON output, the discovery of sub-subcommands, the nodes a trace shows."""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
from types import ModuleType
from typing import Any


def print_json(payload: Any) -> None:
    """Print one JSON document to stdout, the shape every ``--json`` flag promises."""
    json.dump(payload, sys.stdout, indent=2, sort_keys=False, default=str)
    sys.stdout.write("\n")


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
    """Whether ``run`` and ``tick`` print a node's status changes: the plan's primitives and their guards."""
    from bt_meta.bt.actions import PrimitiveAction
    from bt_meta.bt.guards import CheckCondition

    return isinstance(behaviour, (PrimitiveAction, CheckCondition))
