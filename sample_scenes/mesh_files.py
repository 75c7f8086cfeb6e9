"""Fast writers of mesh sequences: Wavefront OBJ (text) and binary little-endian PLY.

All frames of a sequence share the faces, so the face block is formatted once and reused.
OBJ: ``v x y z`` with 6 decimals (1 micrometre in metres) and 1-based ``f`` lines.  PLY: float32
``x y z`` vertices and a ``uchar``-counted ``int`` vertex-index list per face.  Faces may be triangles or
quads (F, 3|4).  Files are written to a temporary name and renamed, so none is ever half-written.

Axes: with ``from_world=True`` the vertices are Blender world coordinates (Z up) and are written in the
format's own axis convention, as Blender's exporter writes them, so that Blender's importer and
``articula.import_scans`` (default axes) both stand them up: OBJ forward -Z, up Y, i.e. (x, y, z) ->
(x, z, -y); PLY as given (forward Y, up Z).  ``from_world=False`` writes the coordinates as given.
"""
from __future__ import annotations

import os

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.formats.axes import format_axes, world_to_file

FORMATS = ("obj", "ply")


def _atomic_write(path, data: bytes) -> None:
    tmp = f"{path}.tmp"
    with open(tmp, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)


class SequenceWriter:
    """Writes frames ``(V, 3)`` of one topology ``faces (F, k)`` as OBJ or PLY files (``from_world``: see
    the module docstring)."""

    def __init__(self, faces: np.ndarray, fmt: str = "obj", from_world: bool = False):
        if fmt not in FORMATS:
            raise ArticulaInputError(f"format: unknown mesh format {fmt!r} (choose from {', '.join(FORMATS)})")
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        if self.faces.ndim != 2 or self.faces.shape[1] not in (3, 4):
            raise ArticulaInputError(f"faces: expected (F, 3) or (F, 4), got {self.faces.shape}")
        self.fmt = fmt
        self.from_world = bool(from_world)
        axes = "forward {}, up {}".format(*format_axes("." + fmt)) if from_world else "axes as given"
        self._comment = f"Articula sample sequence (metres, {axes})"
        self._face_block = self._obj_faces() if fmt == "obj" else self._ply_faces()

    def _obj_faces(self) -> bytes:
        k = self.faces.shape[1]
        line = "f" + " %d" * k + "\n"
        return ((line * len(self.faces)) % tuple((self.faces + 1).ravel().tolist())).encode()

    def _ply_faces(self) -> bytes:
        k = self.faces.shape[1]
        rec = np.empty(len(self.faces), dtype=[("n", "u1"), ("idx", "<i4", (k,))])
        rec["n"], rec["idx"] = k, self.faces
        return rec.tobytes()

    def encode(self, vertices: np.ndarray) -> bytes:
        """The file content for one frame of vertices (V, 3)."""
        v = np.asarray(vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
            raise ArticulaInputError(f"vertices: expected finite (V, 3), got shape {v.shape}")
        if self.from_world:
            v = world_to_file(v, "." + self.fmt)
        if self.fmt == "obj":
            head = (("v %.6f %.6f %.6f\n" * len(v)) % tuple(v.ravel().tolist())).encode()
            return f"# {self._comment}\n".encode() + head + self._face_block
        header = (f"ply\nformat binary_little_endian 1.0\ncomment {self._comment}\n"
                  f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
                  f"element face {len(self.faces)}\nproperty list uchar int vertex_indices\nend_header\n")
        return header.encode("ascii") + v.astype("<f4").tobytes() + self._face_block

    def write(self, path, vertices: np.ndarray) -> None:
        """Write one frame to ``path`` (atomically)."""
        _atomic_write(path, self.encode(vertices))
