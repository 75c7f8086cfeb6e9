"""Read a polygon-mesh file of any supported format, chosen by its extension.

Every reader returns a :class:`~.polymesh.PolyMesh` and raises ``ArticulaInputError`` naming the file
(and line, face or vertex) for anything it cannot use: missing or unreadable files, garbage, indices out
of range, faces with fewer than three corners, NaN/inf coordinates.  :func:`check_mesh` checks a file
from its first bytes and size only (format, declared counts, the size limit), so a list of files can
be checked before any is read.
"""
import os

from ..errors import ArticulaInputError
from .obj import check_obj, read_obj
from .off import check_off, read_off
from .ply import check_ply, read_ply
from .polymesh import PolyMesh
from .stl import check_stl, read_stl

MESH_EXTENSIONS = (".obj", ".ply", ".stl", ".off")
_READERS = {".obj": (check_obj, read_obj), ".ply": (check_ply, read_ply), ".stl": (check_stl, read_stl),
            ".off": (check_off, read_off)}


def _reader(path: str):
    ext = os.path.splitext(path)[1].lower()
    if ext not in _READERS:
        raise ArticulaInputError(f"{path}: unsupported mesh format {ext or '(no extension)'!r}; "
                                 f"use one of {', '.join(MESH_EXTENSIONS)}")
    return _READERS[ext]


def check_mesh(path: str) -> None:
    """Refuse a mesh file from its first bytes and size (see the module docstring); reads a few kB."""
    _reader(path)[0](path)


def read_mesh(path: str) -> PolyMesh:
    """Read an OBJ, PLY, STL or OFF file (chosen by extension)."""
    return _reader(path)[1](path)
