"""Where the shipped data lives, whether bt-meta runs from a checkout or from an installed wheel.

Offers:

* :func:`trees_dir` -- the folder of shipped task files and tree XML (``trees/`` in the repository)
* :func:`robots_dir` -- the folder of robot descriptions (``robots/`` in the repository)
* :func:`shipped_tree` -- the path of one shipped task file or tree by name
"""

from __future__ import annotations

from pathlib import Path

from bt_meta import data
from bt_meta.errors import UserInputError


def _data_dir(name: str) -> Path:
    installed = Path(data.__file__).resolve().parent / name
    if installed.is_dir():
        return installed
    # A checkout (plain or editable install): the folders sit at the top of the repository.
    return Path(__file__).resolve().parent.parent / name


def trees_dir() -> Path:
    return _data_dir("trees")


def robots_dir() -> Path:
    return _data_dir("robots")


def shipped_tree(filename: str) -> Path:
    """Return the path of a shipped task file, e.g. ``shipped_tree("letters.yaml")``."""
    path = trees_dir() / filename
    if not path.is_file():
        available = ", ".join(sorted(p.name for p in trees_dir().iterdir() if p.is_file()))
        raise UserInputError(f"no shipped task file {filename!r}; available: {available}")
    return path
