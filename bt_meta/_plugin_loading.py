"""Importing plugin files from folders, with errors that name the file and the line.

Offers:

* :class:`PluginLoadError` -- a plugin file or entry point that does not import (a located user-input error)
* :func:`plugin_files` -- the ``*.py`` files of a plugin folder a loader picks up, in a stable order
* :func:`import_plugin_file` -- import one file as a module without touching ``sys.path``
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
import traceback
from pathlib import Path
from types import ModuleType

from bt_meta.errors import PluginError, UserInputError


class PluginLoadError(PluginError, UserInputError):
    """A plugin that could not be loaded: the CLI prints ``path:line: message`` and exits 2."""


def plugin_files(folder: Path) -> list[Path]:
    """Every ``*.py`` file directly in ``folder`` except private ones (``_*.py``), sorted by name."""
    return sorted(p for p in folder.glob("*.py") if p.is_file() and not p.name.startswith("_"))


def module_name_for(path: Path) -> str:
    """A module name unique to the file's absolute path, so two folders may both hold ``repair.py``."""
    digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:10]
    stem = "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in path.stem)
    return f"bt_meta_local_plugins.{stem}_{digest}"


def _line_in_file(error: BaseException, path: Path) -> int | None:
    if isinstance(error, SyntaxError) and error.filename and Path(error.filename).resolve() == path.resolve():
        return error.lineno
    line = None
    for frame in traceback.extract_tb(error.__traceback__):
        if frame.filename and Path(frame.filename).resolve() == path.resolve():
            line = frame.lineno
    return line


def import_plugin_file(path: Path) -> ModuleType:
    """Import ``path`` as a fresh module; any exception becomes a :class:`PluginLoadError` at its line."""
    path = path.resolve()
    name = module_name_for(path)
    existing = sys.modules.get(name)
    if existing is not None:
        return existing
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise PluginLoadError("not an importable Python file", path=path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as error:  # a plugin calling sys.exit at import must not end the command
        del sys.modules[name]
        line = _line_in_file(error, path)
        detail = error.msg if isinstance(error, SyntaxError) else str(error)
        column = error.offset if isinstance(error, SyntaxError) else None
        raise PluginLoadError(
            f"plugin file failed to import: {type(error).__name__}: {detail}", path=path, line=line, column=column
        ) from error
    return module
