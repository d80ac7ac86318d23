"""Process-lifetime caches of models parsed from files, so that a worker serving many episodes loads each once.

A campaign worker runs episode after episode, each in a fresh world; what those worlds share is read from files
that do not change between episodes: the robot description, its URDF parsed into collision geometry, the MuJoCo
models mink solves IK on, the URDF pybullet loads (and :mod:`bt_meta.safe_yaml` keeps the last YAML trees it
composed, keyed by their text). Each cache entry is keyed by the **signatures** of the files it
came from (resolved path, size, modification time), so an edited file is read again; callers hand out copies of
whatever a world mutates (the collision geometry gets the scene's objects added), never the cached object itself.

``BT_META_MODEL_CACHE=0`` in the environment turns every cache off (each call reads its files again): the test of
identical outcomes with and without reuse, and ``bt-meta bench episode``'s comparison, run both ways.

Offers:

* :func:`cached` -- the value for a key, computed by a function on a miss (or every time when caching is off)
* :func:`file_signature` -- the part of a key that changes when a file does
* :func:`signature_or_none` -- the same for what may name a file or not
* :func:`enabled` -- whether caching is on
* :func:`clear_entry` / :func:`clear` -- forget one entry / every entry (tests)
"""

from __future__ import annotations

import os
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["cached", "clear", "clear_entry", "enabled", "file_signature", "signature_or_none"]

T = TypeVar("T")

_ENTRIES: dict[Hashable, Any] = {}


def enabled() -> bool:
    """Caching is on unless ``BT_META_MODEL_CACHE`` is ``0`` (read on every call, so tests can switch it)."""
    return os.environ.get("BT_META_MODEL_CACHE", "1").strip() != "0"


def file_signature(path: str | Path | None) -> tuple[str, int, int] | None:
    """(resolved path, size, mtime in ns) of ``path``; ``None`` for no path."""
    if path is None:
        return None
    resolved = Path(path).resolve()
    stat = resolved.stat()
    return (str(resolved), stat.st_size, stat.st_mtime_ns)


def signature_or_none(path: Any) -> tuple[str, int, int] | None:
    """:func:`file_signature` of ``path`` when it names a file, else ``None`` (a scene's name, a missing file: the
    computation keyed by it then reads or fails as it would uncached; a failure is not remembered)."""
    if not path:
        return None
    try:
        return file_signature(path) if Path(path).is_file() else None
    except (OSError, ValueError):
        return None


def cached(key: Hashable, compute: Callable[[], T]) -> T:
    """``compute()``, remembered under ``key`` for the life of the process. An exception is not remembered."""
    if not enabled():
        return compute()
    try:
        return _ENTRIES[key]
    except KeyError:
        value = _ENTRIES[key] = compute()
        return value


def clear_entry(key: Hashable) -> None:
    """Forget one entry (its source files changed in a way its key does not show)."""
    _ENTRIES.pop(key, None)


def clear() -> None:
    _ENTRIES.clear()
