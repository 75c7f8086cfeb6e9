"""Read a polygon-mesh file of any supported format, chosen by its extension.

Every reader returns a :class:`~.polymesh.PolyMesh` and raises ``ArticulaInputError`` naming the file
(and line, face or vertex) for anything it cannot use: missing or unreadable files, garbage, indices out
of range, faces with fewer than three corners, NaN/inf coordinates.
"""
import os

from ..errors import ArticulaInputError
from .obj import read_obj
from .off import read_off
from .ply import read_ply
from .polymesh import PolyMesh
from .stl import read_stl

MESH_EXTENSIONS = (".obj", ".ply", ".stl", ".off")


def read_mesh(path: str) -> PolyMesh:
    """Read an OBJ, PLY, STL or OFF file (chosen by extension)."""
    ext = os.path.splitext(path)[1].lower()
    reader = {".obj": read_obj, ".ply": read_ply, ".stl": read_stl, ".off": read_off}.get(ext)
    if reader is None:
        raise ArticulaInputError(f"{path}: unsupported mesh format {ext or '(no extension)'!r}; "
                                 f"use one of {', '.join(MESH_EXTENSIONS)}")
    return reader(path)
