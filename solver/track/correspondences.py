"""Correspondences between a posed model and one unregistered capture, refreshed before every update.

Model-adaptive mocap dissertation §4.1.2 (its four heuristics, in this order):

1. visibility: model vertices that no camera sees are left out (:mod:`.visibility`); without cameras
   every vertex takes part;
2. normal compatibility: a candidate is accepted only if ``n_a . n_b > 0`` (normals within 90 deg); the
   nearest accepted one among the ``k`` (16) nearest by a k-d tree is taken;
3. two-way matching: every capture point gets the nearest compatible visible model vertex
   ("capture pairs"), every visible model vertex the nearest compatible capture point ("model pairs"),
   so that the visible model and the capture cover each other;
4. uniform outlier removal, variant (B): walking the triangles in order, a triangle that holds no
   removed pair yet loses its largest-distance pair (:func:`trim_per_triangle`); capture pairs are
   walked over the capture's triangles, model pairs over the model's.  A point cloud has no triangles:
   each point with its two nearest neighbours (among the points that have a pair) stands in for one,
   walked in point order.

A capture pair's model point is then moved from the vertex to its foot point on the nearest facing
triangle around that vertex that contains it (``surface=True``; the vertex stays where none does): at the true pose the residual is the scan noise instead of the distance to the
nearest vertex (half the model's edge length), see docs/track.md "Correspondences".  Each pair is stored
as a model point ``sum_i weights[i] * V[vertex_ids[i]]`` (a vertex: ids (v, v, v), weights (1, 0, 0)),
so a solver differentiates it as that combination of skinned vertices.

Units: metres.  Robust weights and the frame's data energy come from :mod:`.robust` (Eq. 4.4-4.6).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.spatial import cKDTree

from .. import parallel
from ..errors import ArticulaInputError
from . import robust
from .visibility import visible_vertices


@dataclasses.dataclass(frozen=True)
class CorrespondenceOptions:
    """Settings of :func:`correspondences` (metres)."""

    k: int = 16                    # nearest neighbours searched for a normal-compatible one
    trim: bool = True              # uniform outlier removal, variant (B)
    surface: bool = True           # capture pairs on the model's surface (else on its nearest vertex)
    eps: float = robust.EPS_M      # Charbonnier eps
    visibility_scale: float = 1.0  # z-buffer resolution as a fraction of each camera's
    depth_tolerance_m: float = 0.005
    depth_tolerance_px: float = 2.0


@dataclasses.dataclass
class Correspondences:
    """Pairs of one frame, ``P`` of them, capture pairs first.  Model point of pair p:
    ``weights[p] @ model_vertices[vertex_ids[p]]``."""

    vertex_ids: np.ndarray        # (P, 3) int64 model vertices of the model point
    weights: np.ndarray           # (P, 3) barycentric weights (sum 1)
    targets: np.ndarray           # (P, 3) capture points (m)
    target_normals: np.ndarray    # (P, 3) their unit normals
    from_capture: np.ndarray      # (P,) bool: capture pair (capture point -> model) or model pair
    capture_index: np.ndarray     # (P,) int64 the capture point
    distances: np.ndarray         # (P,) |target - model point| (m)
    irls_weights: np.ndarray      # (P,) Charbonnier IRLS weights (1/m)
    energy: float                 # Q_n^data of the surviving pairs (m)
    visible: np.ndarray           # (V,) bool model vertices that took part
    stats: dict                   # counts, removal fractions, trimming rounds, seconds per stage

    def model_points(self, model_vertices):
        """``(P, 3)`` model points on the (posed) ``model_vertices (V, 3)``."""
        return np.einsum("pi,pij->pj", self.weights, np.asarray(model_vertices)[self.vertex_ids])


def correspondences(model_vertices, model_triangles, model_normals, points, normals, triangles=None,
                    cameras=None, options: CorrespondenceOptions = CorrespondenceOptions()) -> Correspondences:
    """Two-way, visibility- and normal-checked, trimmed correspondences of a posed model (``model_vertices
    (V, 3)``, ``model_triangles (F, 3)``, unit ``model_normals (V, 3)``) and one capture (``points (N, 3)``,
    unit ``normals (N, 3)``, ``triangles (G, 3)`` or None for a point cloud), optionally seen by
    ``cameras`` (list of ``(cam_to_world (4, 4), Intrinsics)`` in the capture's coordinates)."""
    mv, mt, mn = _as(model_vertices, 3, "model vertices"), _as(model_triangles, 3, "model triangles", int), \
        _as(model_normals, 3, "model normals")
    cp, cn = _as(points, 3, "capture points"), _as(normals, 3, "capture normals")
    ct = None if triangles is None else _as(triangles, 3, "capture triangles", int)
    clock = _Clock()
    visible = visible_vertices(mv, mn, mt, cameras, options.visibility_scale, options.depth_tolerance_m,
                               options.depth_tolerance_px)
    clock.lap("visibility")
    vis_ids = np.flatnonzero(visible)
    cap_model = _nearest_compatible(mv[vis_ids], mn[vis_ids], cp, cn, options.k)
    cap_model = np.where(cap_model >= 0, vis_ids[np.maximum(cap_model, 0)], -1)
    model_cap = np.full(len(mv), -1, dtype=np.int64)
    model_cap[vis_ids] = _nearest_compatible(cp, cn, mv[vis_ids], mn[vis_ids], options.k)
    clock.lap("matching")
    ids, wts = _model_points(mv, mt, mn, cp, cn, cap_model, options.surface)
    clock.lap("surface")
    cap_dist = _pair_distances(cp, ids, wts, mv, cap_model >= 0)
    mod_dist = np.full(len(mv), np.nan)
    has = model_cap >= 0
    mod_dist[has] = np.linalg.norm(cp[model_cap[has]] - mv[has], axis=1)
    stats = {"capture_pairs": int((cap_model >= 0).sum()), "model_pairs": int(has.sum()),
             "visible": int(visible.sum()), "rounds": 0}
    if options.trim:
        cap_tris = ct if ct is not None else cloud_triangles(cp, cap_model >= 0)
        cap_removed, r1 = trim_per_triangle(cap_dist, cap_tris)
        mod_removed, r2 = trim_per_triangle(mod_dist, mt)
        cap_dist[cap_removed], mod_dist[mod_removed] = np.nan, np.nan
        stats["rounds"] = max(r1, r2)
    clock.lap("trimming")
    out = _assemble(mv, cp, cn, ids, wts, cap_dist, mod_dist, model_cap, visible, options.eps)
    out.stats.update(stats, **_removal(stats, out), seconds=clock.laps)
    return out


def _as(array, columns, what, kind=float):
    a = np.asarray(array, dtype=np.int64 if kind is int else np.float64)
    if a.ndim != 2 or a.shape[1] != columns:
        raise ArticulaInputError(f"correspondences: {what} must be an (n, {columns}) array, got shape {a.shape}")
    if kind is float and not np.isfinite(a).all():
        raise ArticulaInputError(f"correspondences: {what} contain NaN or infinite values")
    return a


class _Clock:
    def __init__(self):
        self.laps, self._t = {}, time.perf_counter()

    def lap(self, name):
        now = time.perf_counter()
        self.laps[name] = now - self._t
        self._t = now


def nearest_compatible(points, point_normals, queries, query_normals, k=16):
    """``(Q,)`` index into ``points (N, 3)`` of the nearest point whose normal has a positive dot product
    with the query's, among the ``k`` nearest of each of ``queries (Q, 3)``; -1 where none of them is."""
    return _nearest_compatible(*(np.asarray(a, dtype=np.float64) for a in
                                 (points, point_normals, queries, query_normals)), k)


def _nearest_compatible(points, point_normals, queries, query_normals, k):
    """As :func:`nearest_compatible`: one nearest-neighbour query for all, ``k`` only for the queries
    whose nearest point faces away (the same answer, far fewer k-queries on smooth surfaces)."""
    out = np.full(len(queries), -1, dtype=np.int64)
    if not len(points) or not len(queries):
        return out
    tree = cKDTree(points)
    _, idx = tree.query(queries, k=1, workers=parallel.workers())
    good = np.einsum("ij,ij->i", point_normals[idx], query_normals) > 0
    out[good] = idx[good]
    retry = np.flatnonzero(~good)
    if len(retry) and k > 1:
        kk = min(k, len(points))
        _, cand = tree.query(queries[retry], k=list(range(1, kk + 1)), workers=parallel.workers())
        ok = np.einsum("qkj,qj->qk", point_normals[cand], query_normals[retry]) > 0
        first = np.argmax(ok, axis=1)
        found = ok[np.arange(len(retry)), first]
        out[retry[found]] = cand[found, first[found]]
    return out


def _model_points(mv, mt, mn, cp, cn, cap_model, surface):
    """Model points of the capture pairs: ``(N, 3)`` vertex ids and weights (rows without a pair:
    vertex 0, weight 0)."""
    ids = np.repeat(np.maximum(cap_model, 0)[:, None], 3, axis=1)
    wts = np.zeros((len(cp), 3))
    wts[cap_model >= 0, 0] = 1.0
    if surface and len(mt):
        rows = np.flatnonzero(cap_model >= 0)
        tri, bary = closest_on_one_ring(mv, mt, cp[rows], cn[rows], cap_model[rows])
        on = tri >= 0
        ids[rows[on]] = mt[tri[on]]
        wts[rows[on]] = bary[on]
    return ids, wts


def closest_on_one_ring(vertices, triangles, queries, query_normals, vertex):
    """For each query ``(Q, 3)``, its foot point on the nearest of the triangles around its model
    ``vertex (Q,)`` that contain the foot point of the query in their plane and whose face normal has a
    positive dot product with the query's normal: ``(triangle (Q,), barycentric (Q, 3))``; triangle -1
    where there is none (the query lies over an edge or the vertex itself: the vertex then stands)."""
    ring = one_ring_table(triangles, len(vertices))[vertex]            # (Q, R), -1 = padding
    tri = np.maximum(ring, 0)
    a = vertices[triangles[:, 0]]
    e1, e2 = vertices[triangles[:, 1]] - a, vertices[triangles[:, 2]] - a
    normal = np.cross(e1, e2)
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((e1, e1), (e1, e2), (e2, e2)))
    den = d00 * d11 - d01 * d01
    flat = den <= 1e-12 * np.maximum(d00 * d11, 1e-300)
    inv = np.where(flat, 0.0, 1.0 / np.where(flat, 1.0, den))
    rel = queries[:, None, :] - a[tri]                                  # (Q, R, 3)
    p1, p2 = np.einsum("qrj,qrj->qr", rel, e1[tri]), np.einsum("qrj,qrj->qr", rel, e2[tri])
    v = (d11[tri] * p1 - d01[tri] * p2) * inv[tri]
    w = (d00[tri] * p2 - d01[tri] * p1) * inv[tri]
    height = np.abs(np.einsum("qrj,qrj->qr", rel, normal[tri])) / np.sqrt(np.maximum(den, 1e-300))[tri]
    facing = np.einsum("qrj,qj->qr", normal[tri], query_normals) > 0
    ok = (ring >= 0) & ~flat[tri] & facing & (v >= 0) & (w >= 0) & (v + w <= 1)
    best = np.argmin(np.where(ok, height, np.inf), axis=1)
    rows = np.arange(len(vertex))
    found = ok[rows, best]
    out_tri = np.where(found, ring[rows, best], -1)
    vb, wb = v[rows, best], w[rows, best]
    bary = np.where(found[:, None], np.stack([1.0 - vb - wb, vb, wb], axis=1), 0.0)
    return out_tri, bary


def one_ring_table(triangles, n_vertices):
    """``(V, R)`` ids of the triangles around each vertex, padded with -1 (R = largest valence)."""
    corner_vertex = triangles.ravel()
    order = np.argsort(corner_vertex, kind="stable")
    counts = np.bincount(corner_vertex, minlength=n_vertices)
    starts = np.cumsum(counts) - counts
    table = np.full((n_vertices, max(int(counts.max(initial=0)), 1)), -1, dtype=np.int64)
    sorted_vertex = corner_vertex[order]
    table[sorted_vertex, np.arange(len(order)) - starts[sorted_vertex]] = order // 3
    return table


def _pair_distances(cp, ids, wts, mv, has):
    """``(N,)`` distance of each capture point to its model point, NaN without a pair."""
    out = np.full(len(cp), np.nan)
    rows = np.flatnonzero(has)
    model = np.einsum("pi,pij->pj", wts[rows], mv[ids[rows]])
    out[rows] = np.linalg.norm(cp[rows] - model, axis=1)
    return out


def cloud_triangles(points, has_pair):
    """Stand-in triangles ``(T, 3)`` for a point cloud: each point that has a pair with its two nearest
    neighbours among those points, in point order."""
    rows = np.flatnonzero(has_pair)
    if len(rows) < 3:
        return np.zeros((0, 3), dtype=np.int64)
    _, nn = cKDTree(points[rows]).query(points[rows], k=[1, 2, 3], workers=parallel.workers())
    return rows[nn]


def trim_per_triangle(distances, triangles):
    """Uniform outlier removal, variant (B): walk ``triangles (T, 3)`` in order; a triangle already
    holding a removed pair is skipped, any other loses its largest-distance pair (ties: first corner).
    ``distances (N,)`` per vertex, NaN = no pair there (triangles without pairs are ignored).
    Returns ``(removed (N,) bool, rounds)``.

    The sequential walk is evaluated in vectorised rounds: a triangle is decided once no undecided
    earlier triangle would remove one of its vertices; it is skipped if a decided earlier triangle
    removed one.  Each round decides at least the first undecided triangle, usually most of them."""
    d = np.where(np.isnan(distances), -np.inf, np.asarray(distances, dtype=np.float64))
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    tris = tris[np.isfinite(d[tris]).any(axis=1)]
    n, count = len(d), len(tris)
    victim = tris[np.arange(count), np.argmax(d[tris], axis=1)]
    removed_by = np.full(n, count, dtype=np.int64)
    undecided = np.arange(count)
    rounds = 0
    while len(undecided):
        rounds += 1
        first = np.full(n, count, dtype=np.int64)
        np.minimum.at(first, victim[undecided], undecided)
        corners = tris[undecided]
        skip = (removed_by[corners] < undecided[:, None]).any(axis=1)
        act = ~skip & (first[corners] >= undecided[:, None]).all(axis=1)
        np.minimum.at(removed_by, victim[undecided[act]], undecided[act])
        undecided = undecided[~(skip | act)]
    return removed_by < count, rounds


def _assemble(mv, cp, cn, ids, wts, cap_dist, mod_dist, model_cap, visible, eps):
    """The surviving pairs as one :class:`Correspondences` (capture pairs first)."""
    cap_rows = np.flatnonzero(~np.isnan(cap_dist))
    mod_rows = np.flatnonzero(~np.isnan(mod_dist))
    target_idx = np.concatenate([cap_rows, model_cap[mod_rows]])
    vertex_ids = np.concatenate([ids[cap_rows], np.repeat(mod_rows[:, None], 3, axis=1)])
    weights = np.concatenate([wts[cap_rows], np.tile([1.0, 0.0, 0.0], (len(mod_rows), 1))])
    distances = np.concatenate([cap_dist[cap_rows], mod_dist[mod_rows]])
    return Correspondences(
        vertex_ids=vertex_ids, weights=weights, targets=cp[target_idx], target_normals=cn[target_idx],
        from_capture=np.r_[np.ones(len(cap_rows), bool), np.zeros(len(mod_rows), bool)],
        capture_index=target_idx, distances=distances, irls_weights=robust.irls_weights(distances, eps),
        energy=robust.data_energy(distances, eps), visible=visible, stats={})


def _removal(stats, out):
    """Fractions of each direction's pairs removed by trimming."""
    kept_cap = int(out.from_capture.sum())
    kept_mod = len(out.from_capture) - kept_cap
    frac = [1.0 - kept / total if total else 0.0 for kept, total in
            ((kept_cap, stats["capture_pairs"]), (kept_mod, stats["model_pairs"]))]
    return {"removed_capture": frac[0], "removed_model": frac[1]}
