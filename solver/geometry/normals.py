"""Vertex normals and vertex areas of a triangle mesh, shared by both trackers' correspondences, visibility,
surfaces, checks and start searches."""
from __future__ import annotations

import numpy as np


def vertex_normals(vertices, triangles):
    """Unit area-weighted vertex normals ``(V, 3)`` of a mesh (``vertices (V, 3)``, ``triangles (F, 3)``,
    counter-clockwise seen from outside); zero for vertices in no (non-degenerate) triangle."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    area_normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    out = np.zeros_like(v)
    for corner in range(3):
        out += np.stack([np.bincount(f[:, corner], area_normals[:, i], len(v)) for i in range(3)], axis=1)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def vertex_areas(vertices, triangles):
    """A third of the area of every triangle at each of its vertices ``(V,)`` (squared units of the
    vertices)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    return np.bincount(f.ravel(), np.repeat(area / 3.0, 3), len(v))
