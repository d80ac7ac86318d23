"""Blackboard entries as BehaviorTree.CPP scripts and update-watching nodes see them.

py_trees keeps one global blackboard; the XML reader has already mapped every key of a SubTree to the root key it
denotes. BT.CPP also counts the writes to each entry (``sequence_id``) so that ``WasEntryUpdated`` and
``SkipUnlessUpdated`` can tell whether an entry changed; built-in nodes and scripts write through :func:`write`
so the count is kept.

Offers:

* :func:`write`, :func:`unset`, :func:`exists`, :func:`read`, :func:`sequence_id` -- entries by absolute key
* :class:`BlackboardEnvironment` -- a script environment: script names -> root keys (from the reader), enums
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import py_trees

from bt_meta.bt.script.errors import ScriptRuntimeError

_SEQUENCE: dict[str, int] = {}


def absolute_key(key: str) -> str:
    key = key.lstrip("@")
    return key if key.startswith("/") else "/" + key


def write(key: str, value: Any) -> None:
    key = absolute_key(key)
    py_trees.blackboard.Blackboard.set(key, value)
    _SEQUENCE[key] = _SEQUENCE.get(key, 0) + 1


def unset(key: str) -> None:
    key = absolute_key(key)
    py_trees.blackboard.Blackboard.storage.pop(key, None)


def exists(key: str) -> bool:
    return absolute_key(key) in py_trees.blackboard.Blackboard.storage


def read(key: str) -> Any:
    return py_trees.blackboard.Blackboard.storage[absolute_key(key)]


def sequence_id(key: str) -> int | None:
    """How many times the entry was written, ``None`` when it does not exist."""
    key = absolute_key(key)
    if key not in py_trees.blackboard.Blackboard.storage:
        return None
    return _SEQUENCE.get(key, 0)


class BlackboardEnvironment:
    """The environment a script of one node runs in: ``keys`` maps the names it uses to root keys."""

    def __init__(self, keys: Mapping[str, str] | None = None, enums: Mapping[str, int] | None = None) -> None:
        self.keys = dict(keys or {})
        self.enums = dict(enums or {})

    def key(self, name: str) -> str:
        return absolute_key(self.keys.get(name, name))

    def exists(self, name: str) -> bool:
        return self.key(name) in py_trees.blackboard.Blackboard.storage

    def get(self, name: str) -> Any:
        try:
            return py_trees.blackboard.Blackboard.storage[self.key(name)]
        except KeyError:
            raise ScriptRuntimeError(f"Variable not found: {name}") from None

    def set(self, name: str, value: Any) -> None:
        write(self.key(name), value)
