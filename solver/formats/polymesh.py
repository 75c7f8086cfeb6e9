"""Polygon meshes as the mesh readers return them, and what the readers share: reading a file,
parsing numbers, validating and packing the result.

Polygons are kept as Blender keeps them: ``face_sizes`` (F,) corners per face and ``corner_verts`` (C,)
the vertex of every corner, faces one after another.  Faces that use one vertex twice (degenerate, e.g.
after welding an STL) are dropped, as Blender's own importers do.  Problems raise
``ArticulaInputError`` with a message naming the file (and line, face or vertex).  Faces and vertices
in messages are numbered from 1 (the first face is face 1); a vertex *index* as written in the file is
quoted as written, with the file format's valid range.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError


@dataclass(frozen=True, eq=False)
class PolyMesh:
    """A polygon mesh: ``vertices`` (V,3) float64, ``face_sizes`` (F,) int32, ``corner_verts`` (C,) int32
    with C = sum(face_sizes)."""
    vertices: np.ndarray
    face_sizes: np.ndarray
    corner_verts: np.ndarray

    @property
    def face_starts(self) -> np.ndarray:
        """(F,) int32 index of each face's first corner in ``corner_verts``."""
        starts = np.zeros(len(self.face_sizes), np.int32)
        np.cumsum(self.face_sizes[:-1], out=starts[1:])
        return starts

    def triangles(self) -> np.ndarray:
        """(T,3) int32 fan triangulation of every face (a triangle stays itself)."""
        sizes = self.face_sizes.astype(np.int64)
        starts = self.face_starts.astype(np.int64)
        ntri = sizes - 2
        first = np.repeat(starts, ntri)
        k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # 0..n-3 within each face
        cv = self.corner_verts
        return np.stack([cv[first], cv[first + k + 1], cv[first + k + 2]], axis=1).astype(np.int32)

    def topology_difference(self, other: "PolyMesh") -> str | None:
        """None when ``other`` has the same vertex count and identical faces, else how it differs."""
        if len(other.vertices) != len(self.vertices):
            return f"vertex count {len(other.vertices)} vs {len(self.vertices)}"
        if len(other.face_sizes) != len(self.face_sizes):
            return f"face count {len(other.face_sizes)} vs {len(self.face_sizes)}"
        bad = np.flatnonzero(other.face_sizes != self.face_sizes)
        if bad.size:
            k = int(bad[0])
            return f"face {k + 1} has {other.face_sizes[k]} corners vs {self.face_sizes[k]}"
        diff = np.flatnonzero(other.corner_verts != self.corner_verts)
        if diff.size:
            face = int(np.searchsorted(self.face_starts, diff[0], side="right") - 1)
            return f"face {face + 1} differs (vertices {_face(other, face)} vs {_face(self, face)}, numbered from 1)"
        return None


def _face(mesh: PolyMesh, k: int) -> list:
    """Vertices of face ``k`` numbered from 1 (for messages)."""
    s = int(mesh.face_starts[k])
    return (mesh.corner_verts[s:s + int(mesh.face_sizes[k])] + 1).tolist()


def parse_numbers(tokens, dtype, path: str, what: str) -> np.ndarray:
    """Number tokens (bytes, any shape) as an array of ``dtype``; a bad token raises naming ``what``."""
    try:
        return np.array(tokens, dtype=bytes).astype(dtype)
    except (ValueError, OverflowError) as exc:
        raise ArticulaInputError(f"{path}: bad {what}: {exc}") from None


def fast_numbers(text: bytes, dtype, expected):
    """Whitespace-separated numbers at C speed, or None when parsing fails or (``expected`` given) the
    count differs.  (numpy < 2 stops at a bad token with a warning instead of raising: the count or the
    caller's own check catches that.)"""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            out = np.fromstring(text, dtype=dtype, sep=" ")
    except ValueError:
        return None
    return out if expected is None or out.size == expected else None


def check_finite(vertices: np.ndarray, path: str) -> None:
    """Raise naming the first vertex (numbered from 1) with a NaN or infinite coordinate."""
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ArticulaInputError(f"{path}: vertex {i + 1} has a non-finite coordinate {vertices[i].tolist()} "
                                 f"({int(bad.sum())} such vertices)")


def finish_mesh(path: str, vertices: np.ndarray, sizes: np.ndarray, corners: np.ndarray,
                index_base: int = 0) -> PolyMesh:
    """A reader's result (vertices (V, 3), face sizes (F,), corner vertex indices (C,), 0-based) validated
    and packed: finite vertices, faces with >= 3 corners and indices in range; faces that use a vertex
    twice are dropped.  ``index_base``: what the file's first vertex index is (1 for OBJ, 0 for PLY and
    OFF), so a bad index is quoted as written in the file."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    sizes = np.asarray(sizes, np.int64)
    corners = np.asarray(corners, np.int64)
    check_finite(vertices, path)
    if sizes.size and sizes.min() < 3:
        k = int(np.flatnonzero(sizes < 3)[0])
        raise ArticulaInputError(f"{path}: face {k + 1} has {sizes[k]} corners (at least 3 needed)")
    if corners.size:
        out = (corners < 0) | (corners >= len(vertices))
        if out.any():
            c = int(np.flatnonzero(out)[0])
            k = int(np.searchsorted(np.cumsum(sizes), c, side="right"))
            nv = len(vertices)
            raise ArticulaInputError(f"{path}: face {k + 1} uses vertex index {corners[c] + index_base}, but the "
                                     f"file has {nv} vertices (indices {index_base}..{nv - 1 + index_base})")
        sizes, corners = _drop_degenerate(sizes, corners)
    return PolyMesh(vertices, sizes.astype(np.int32), corners.astype(np.int32))


def _drop_degenerate(sizes: np.ndarray, corners: np.ndarray):
    """Remove faces that use a vertex more than once."""
    if sizes.size and (sizes == sizes[0]).all():     # one face size: a row-wise check
        rows = np.sort(corners.reshape(len(sizes), -1), axis=1)
        bad = (rows[:, 1:] == rows[:, :-1]).any(axis=1)
        if not bad.any():
            return sizes, corners
        return sizes[~bad], corners.reshape(len(sizes), -1)[~bad].reshape(-1)
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    order = np.lexsort((corners, face_of))
    same = (face_of[order][1:] == face_of[order][:-1]) & (corners[order][1:] == corners[order][:-1])
    if not same.any():
        return sizes, corners
    bad_faces = np.zeros(len(sizes), bool)
    bad_faces[face_of[order][1:][same]] = True
    return sizes[~bad_faces], corners[~bad_faces[face_of]]
