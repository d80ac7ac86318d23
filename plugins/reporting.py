"""The default meta-reasoner hook: reports a failure and decides nothing.

Until a meta-reasoner plugin is installed, a recorded failure is logged on the ``bt_meta.meta`` logger with its
kind, step, node and evidence keys; the run goes on with the tree's own FAILURE.

Offers:

* :func:`bt_meta_on_failure` -- log one line per failure; returns no notes
"""

from __future__ import annotations

import logging
from typing import Any

from bt_meta.plugins import hookimpl

log = logging.getLogger("bt_meta.meta")


@hookimpl(trylast=True)
def bt_meta_on_failure(failure: Any, context: Any) -> None:
    keys = ", ".join(sorted(failure.evidence)) or "none"
    log.info("failure reported (no meta-reasoner installed): %s; evidence: %s", failure.summary(), keys)
