"""The planning budget every command gives the planner unless told otherwise.

A search that cannot end -- a method that decomposes a task into itself forever, an exponential problem -- then
stops with the outcome ``budget_exhausted`` (exit status 1) instead of running until it is killed. The shipped
problems plan in well under a second and 20,000 expansions; ``bt-meta plan --max-nodes/--max-seconds`` and the
``plan_options`` of :func:`bt_meta.bt.compiler.compile_task_file` give more. The library's
:func:`bt_meta.htn.plan` itself has no default budget: a program calling it chooses.

Offers:

* :data:`DEFAULT_MAX_NODES` -- 10,000,000 task expansions
* :data:`DEFAULT_MAX_SECONDS` -- 10 seconds
* :func:`with_default_budget` -- planner options with the defaults filled in where none is given
"""

from __future__ import annotations

from typing import Any

DEFAULT_MAX_NODES = 10_000_000
DEFAULT_MAX_SECONDS = 10.0


def with_default_budget(options: dict[str, Any] | None) -> dict[str, Any]:
    """``options`` with ``max_nodes`` / ``max_seconds`` set to the defaults when absent or ``None``."""
    filled = dict(options or {})
    if filled.get("max_nodes") is None:
        filled["max_nodes"] = DEFAULT_MAX_NODES
    if filled.get("max_seconds") is None:
        filled["max_seconds"] = DEFAULT_MAX_SECONDS
    return filled
