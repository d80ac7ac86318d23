"""Mesh files for object types: where a catalogue's ``mesh:`` names a file, and the vertices in it.

pybullet loads the file itself (OBJ or STL; a moving body collides as its convex hull); bt-meta reads the
vertices for what it computes from a model's outline (resting height, extent, the finger band of a grasp) and for
the collision checker's convex hull (coal), so the three agree.

Offers:

* :func:`read_vertices` -- an OBJ's or STL's (binary or ASCII) vertices as an (n, 3) array, in the file's units
* :func:`distribution_file` -- a file inside an installed distribution's data (``example-robot-data``'s meshes)
* :class:`MeshError` -- a file that is missing, of another format, or holds no vertices
"""

from __future__ import annotations

import importlib.metadata
import struct
from pathlib import Path

import numpy as np

from bt_meta.errors import BtMetaError

__all__ = ["MeshError", "distribution_file", "read_vertices"]

FORMATS = (".obj", ".stl")


class MeshError(BtMetaError):
    """A mesh file that cannot be used."""


def distribution_file(distribution: str, relative: str) -> Path:
    """``relative`` inside the installed ``distribution``'s files (a data package such as example-robot-data,
    whose meshes live under ``cmeel.prefix/share``)."""
    try:
        dist = importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        raise MeshError(f"distribution {distribution!r} is not installed") from None
    path = Path(str(dist.locate_file(relative)))
    if not path.is_file():
        raise MeshError(f"{relative} is not a file of the installed distribution {distribution!r}")
    return path


def read_vertices(path: str | Path) -> np.ndarray:
    """The vertices of an OBJ or STL file, (n, 3), unscaled."""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise MeshError(f"{path}: a mesh is an OBJ or STL file, not {path.suffix or 'a file without suffix'}")
    try:
        data = path.read_bytes()
    except OSError as error:
        raise MeshError(f"{path}: cannot read the mesh ({error.strerror or error})") from None
    vertices = _obj(data) if path.suffix.lower() == ".obj" else _stl(data)
    if len(vertices) < 4:
        raise MeshError(f"{path}: the mesh has {len(vertices)} vertices; a solid needs at least 4")
    return vertices


def _obj(data: bytes) -> np.ndarray:
    rows = []
    for line in data.decode("utf-8", errors="replace").splitlines():
        fields = line.split()
        if len(fields) >= 4 and fields[0] == "v":
            rows.append([float(v) for v in fields[1:4]])
    return np.array(rows, dtype=float).reshape(-1, 3)


def _stl(data: bytes) -> np.ndarray:
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * count == len(data):  # binary: 80-byte header, count, 50 bytes per triangle
            triangles = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                                      count=count, offset=84)
            return np.unique(triangles["v"].reshape(-1, 3).astype(float), axis=0)
    rows = [[float(v) for v in line.split()[1:4]] for line in data.decode("utf-8", errors="replace").splitlines()
            if line.strip().startswith("vertex")]
    return np.unique(np.array(rows, dtype=float).reshape(-1, 3), axis=0)
