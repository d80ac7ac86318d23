"""Where the episodic memory file lives, and the ``--memory`` flag every memory-using command shares.

Offers:

* :data:`ENV_VAR` -- ``BT_META_MEMORY``, the environment variable that chooses the memory file
* :data:`DEFAULT_RELATIVE` -- ``.bt-meta/memory.sqlite``, the default, relative to the user's project folder (cwd)
* :func:`add_memory_argument` -- add ``--memory PATH`` to a command's parser
* :func:`resolve_memory_path` -- the file a command should use: ``--memory``, else ``$BT_META_MEMORY``, else default

The memory belongs to the user's project, not to bt-meta's installation: a demonstration recorded in one project
folder is never seen by another unless the user points both at the same file.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Mapping
from pathlib import Path

ENV_VAR = "BT_META_MEMORY"
DEFAULT_RELATIVE = Path(".bt-meta") / "memory.sqlite"


def add_memory_argument(parser: argparse.ArgumentParser) -> None:
    """Give a command the shared ``--memory PATH`` option (read back with :func:`resolve_memory_path`)."""
    parser.add_argument(
        "--memory",
        metavar="PATH",
        default=None,
        help=f"episodic memory file (default: ${ENV_VAR}, else ./{DEFAULT_RELATIVE.as_posix()} in the current folder)",
    )


def resolve_memory_path(
    args: argparse.Namespace | None = None,
    *,
    environ: Mapping[str, str] | None = None,
    cwd: Path | None = None,
    writing: bool = False,
) -> Path:
    """The absolute memory path: the ``--memory`` flag wins over ``$BT_META_MEMORY``, which wins over the default.

    An empty flag or variable counts as unset. ``~`` is expanded; relative paths are taken from ``cwd``. With
    ``writing``, a path the user chose whose folder does not exist is a
    :class:`~bt_meta.memory.MemoryFileError` (a mistyped ``--memory`` must not silently create folders); only the
    default's own ``.bt-meta/`` folder is created when the memory is opened.
    """
    environ = os.environ if environ is None else environ
    base = Path.cwd() if cwd is None else cwd
    chosen = getattr(args, "memory", None) if args is not None else None
    if not chosen:
        chosen = environ.get(ENV_VAR) or None
    if chosen:
        from bt_meta.errors import UserInputError
        from bt_meta.user_files import check_path_text

        chosen = check_path_text(chosen, "memory file", UserInputError)
    path = Path(chosen).expanduser() if chosen else DEFAULT_RELATIVE
    if not path.is_absolute():
        path = base / path
    if writing and chosen and not path.parent.is_dir():
        from bt_meta.memory.schema import MemoryFileError

        raise MemoryFileError(path, f"the folder {path.parent} does not exist (bt-meta creates only the default "
                                    f"./{DEFAULT_RELATIVE.as_posix()}; create the folder or choose another --memory)")
    return path
