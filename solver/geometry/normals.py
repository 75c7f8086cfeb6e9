"""Vertex normals of a triangle mesh, shared by both trackers' correspondences, visibility and surfaces."""
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
