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
from scipy.spatial import cKDTree

from ..errors import ArticulaInputError
from ..geometry.surface_distance import closest_points_on_triangles, distance_to_surface, error_statistics

FOOT_CANDIDATES = 4     # nearest centroids tried first for a foot point; the rest by an exact ball query
FOOT_TOL = 1e-12        # a candidate within FOOT_TOL x (coordinate scale of the point) of the distance is the foot


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
    d = distance_to_surface(points, vertices, faces)
    N = len(points)
    feet, which = np.zeros((N, 3)), np.zeros(N, dtype=np.int64)
    if N == 0:
        return d, feet, which
    tri = vertices[faces]                                                  # (F, 3, 3)
    centre = tri.mean(axis=1)
    rmax = float(np.sqrt(((tri - centre[:, None]) ** 2).sum(axis=2).max()))
    tol = FOOT_TOL * (np.abs(tri).max() + np.abs(points).max(axis=1) + rmax)           # (N,): rounding
    tree = cKDTree(centre)
    k = min(FOOT_CANDIDATES, len(faces))
    cand = tree.query(points, k)[1].reshape(N, k)
    best = np.full(N, np.inf)
    rows = np.arange(N)
    for j in range(k):                                  # only the points not yet resolved
        t = cand[rows, j]
        q = closest_points_on_triangles(points[rows], tri[t, 0], tri[t, 1], tri[t, 2])
        dist = np.linalg.norm(q - points[rows], axis=1)
        better = dist < best[rows]
        r = rows[better]
        best[r], feet[r], which[r] = dist[better], q[better], t[better]
        rows = rows[best[rows] > d[rows] + tol[rows]]
    if len(rows):                                       # exact fallback: every triangle that can hold the foot
        lists = tree.query_ball_point(points[rows], d[rows] + rmax + tol[rows] + 1e-9 * rmax)
        counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(rows))
        t = np.fromiter((x for ids in lists for x in ids), dtype=np.int64, count=int(counts.sum()))
        p = np.repeat(rows, counts)
        q = closest_points_on_triangles(points[p], tri[t, 0], tri[t, 1], tri[t, 2])
        dist = np.linalg.norm(q - points[p], axis=1)
        order = np.lexsort((dist, p))                   # per point, its nearest candidate first
        first = order[np.r_[0, np.cumsum(counts)[:-1]]]
        feet[rows], which[rows] = q[first], t[first]
    return d, feet, which


def robust_stats(d) -> dict:
    """``{"mean", "std", "median", "mad", "iqr"}`` of the numbers ``d`` (any shape; the units of ``d``),
    as the dissertation defines them (module docstring); NaN for an empty input.  Example:
    {1, 2, 3, 4, 100} -> median 3, MAD 1, Q1 1.5, Q3 52, IQR 50.5."""
    stats = error_statistics(d)
    return {key: stats[key] for key in ("mean", "std", "median", "mad", "iqr")}
