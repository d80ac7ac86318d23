"""BehaviorTree.CPP's SKIPPED status, which py_trees does not have.

A node that is skipped (a ``_skipIf`` that holds, a ``_while`` that does not, every child of a control node
skipped) *returns* SKIPPED to its parent but keeps its own status, as BT.CPP does: a leaf stays IDLE (py_trees'
INVALID), a control node that had set itself RUNNING stays RUNNING. The returned value lives in
``behaviour.bt_skipped`` for the tick it happened in.

Offers:

* :data:`SKIPPED` -- the returned status (``.name == .value == "SKIPPED"``)
* :data:`Returned` -- a py_trees Status or SKIPPED
* :func:`returned` -- what a behaviour returned on its last tick
* :func:`mark` -- record what a behaviour returned (sets or clears ``bt_skipped``)
* :func:`parse_status` -- a status written in XML -> the status
"""

from __future__ import annotations

from typing import Union

import py_trees
from py_trees.common import Status


class _Skipped:
    name = "SKIPPED"
    value = "SKIPPED"

    def __repr__(self) -> str:
        return "SKIPPED"


SKIPPED = _Skipped()
Returned = Union[Status, _Skipped]  # noqa: UP007


def returned(behaviour: py_trees.behaviour.Behaviour) -> Returned:
    if getattr(behaviour, "bt_skipped", False):
        return SKIPPED
    return behaviour.status


def mark(behaviour: py_trees.behaviour.Behaviour, result: Returned) -> None:
    behaviour.bt_skipped = result is SKIPPED


_STATUSES: dict[str, Returned] = {
    "SUCCESS": Status.SUCCESS,
    "FAILURE": Status.FAILURE,
    "RUNNING": Status.RUNNING,
    "SKIPPED": SKIPPED,
}


def parse_status(text: str) -> Returned:
    """"SUCCESS" / "FAILURE" / "RUNNING" / "SKIPPED" -> the status (``ValueError`` otherwise)."""
    try:
        return _STATUSES[text.strip()]
    except KeyError:
        raise ValueError(f"expected one of {', '.join(_STATUSES)}, got {text!r}") from None
