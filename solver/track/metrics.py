"""Residual metrics of tracking: scan-point-to-model distances and their robust statistics.

Model-adaptive mocap dissertation §4.2 (the evaluation's metrics, Eq. 4.17-4.18): for every capture
point, the Euclidean distance to the closest point of the fitted model's triangles (one direction,
capture -> model), summarised by mean, standard deviation, median (MED), MAD = median |x - MED| and
IQR = Q3 - Q1, where Q1 / Q3 are the medians of the lower / upper halves (the middle element left out
for an odd count), as the dissertation defines them.

The distances are exact (vertex, edge and face regions of every triangle; zero-area triangles by their
edges): :func:`solver.geometry.surface_distance.distance_to_surface` bounds each point by its
nearest-centroid triangle and evaluates every triangle whose bounding sphere and disc can beat that
bound (cKDTree searches).  This module adds the input checks and the foot points.  Units: metres.
"""
import numpy as np

from ..errors import ArticulaInputError
from ..geometry.surface_distance import closest_on_surface, distance_to_surface, error_statistics



def _array(name, x, dtype=np.float64):
    a = np.asarray(x, dtype=dtype)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ArticulaInputError(f"{name}: expected shape (n, 3), got {a.shape}")
    if a.dtype.kind == "f":
        bad = np.argwhere(~np.isfinite(a))
        if len(bad):
            raise ArticulaInputError(f"{name}: non-finite value at row {int(bad[0, 0])}")
    return a


def _mesh(points, vertices, faces):
    """Checked ``(points (N, 3), vertices (V, 3), faces (F, 3) int64)``."""
    points, vertices = _array("points", points), _array("vertices", vertices)
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise ArticulaInputError(f"faces: expected shape (F, 3) with F > 0, got {f.shape}")
    if f.dtype.kind not in "iu":
        raise ArticulaInputError(f"faces: expected integer vertex indices, got {f.dtype}")
    if f.min() < 0 or f.max() >= len(vertices):
        raise ArticulaInputError(f"faces: vertex indices must lie in 0..{len(vertices) - 1}")
    return points, vertices, f.astype(np.int64)


def point_to_mesh(points, vertices, faces) -> np.ndarray:
    """``(N,)`` float64 distance (m) of each point ``(N, 3)`` to the closest point of the triangle mesh
    ``vertices (V, 3)``, ``faces (F, 3)`` (exact up to rounding; module docstring).  Raises
    :class:`ArticulaInputError` for wrong shapes, non-finite coordinates or face indices out of range."""
    points, vertices, faces = _mesh(points, vertices, faces)
    return distance_to_surface(points, vertices, faces)


def closest_points(points, vertices, faces):
    """``(distances (N,), feet (N, 3), triangles (N,))``: :func:`point_to_mesh` and, per point, a closest
    point of the surface and the index of a triangle holding it (ties: any).  The triangles of the
    ``FOOT_CANDIDATES`` nearest centroids are tried first; a point none of them reaches within rounding
    of its exact distance d gets every triangle whose centroid lies within d + (largest centroid-to-corner
    radius): a triangle at distance d has its centroid within d + its radius, so one is among them."""
    points, vertices, faces = _mesh(points, vertices, faces)
    return closest_on_surface(points, vertices, faces)


def robust_stats(d) -> dict:
    """``{"mean", "std", "median", "mad", "iqr"}`` of the numbers ``d`` (any shape; the units of ``d``),
    as the dissertation defines them (module docstring); NaN for an empty input.  Example:
    {1, 2, 3, 4, 100} -> median 3, MAD 1, Q1 1.5, Q3 52, IQR 50.5."""
    stats = error_statistics(d)
    return {key: stats[key] for key in ("mean", "std", "median", "mad", "iqr")}
