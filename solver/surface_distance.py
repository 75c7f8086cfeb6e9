"""Exact point-to-surface distances of triangle meshes and the error statistics of spec §6.1.

* :func:`closest_points_on_triangles` — the closest point of triangle (a, b, c) to p, per row, by the
  Voronoi-region test (vertex, edge or face region; Ericson, *Real-Time Collision Detection* §5.1.5,
  written from the description), vectorised over rows.
* :func:`distance_to_surface` — distance of every query point to the nearest triangle of a mesh,
  exactly: the triangles around the nearest mesh vertex give an upper bound d; a triangle can only be
  closer if its bounding sphere (centroid, radius about the centroid) comes within d, so only triangles
  whose centroid lies within d + radius are tested (k-d trees per group of similar radii), in chunks.
* :func:`per_vertex_scan_distances` — per frame m, the distance of points m to surface m, ``(M, N)``; the
  heat map of a learned rig is its mean over m of scan vertex v to the posed model's surface.
* :func:`error_statistics` — mean, std, median, MAD = median |x − median|, IQR = Q3 − Q1 and max.
  Q1/Q3 are the medians of the lower/upper halves (the middle element excluded for odd n), as the
  spec defines them.

Units: those of the input (metres in Articula); :func:`error_statistics` only summarises numbers.
"""
import numpy as np
from scipy.spatial import cKDTree

CHUNK_PAIRS = 2_000_000     # point/triangle pairs evaluated at once


def closest_points_on_triangles(p, a, b, c):
    """Closest points ``(N, 3)`` on triangles ``(a, b, c)`` (each ``(N, 3)``) to points ``p (N, 3)``.
    Degenerate triangles (zero area) give the closest point of their edges."""
    p, a, b, c = (np.asarray(x, dtype=np.float64) for x in (p, a, b, c))
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c

    def dot(x, y):
        return np.einsum("ni,ni->n", x, y)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2

    def ratio(num, den):
        safe = np.where(np.abs(den) > 0, den, 1.0)
        return np.clip(np.where(np.abs(den) > 0, num / safe, 0.0), 0.0, 1.0)[:, None]

    # face region first; the checks below override it in increasing priority
    den = va + vb + vc
    v, w = ratio(vb, den), ratio(vc, den)
    out = a + ab * v + ac * w
    regions = [
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + ratio(d4 - d3, (d4 - d3) + (d5 - d6)) * (c - b)),  # BC
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ratio(d2, d2 - d6) * ac),                                 # AC
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ratio(d1, d1 - d3) * ab),                                 # AB
        ((d6 >= 0) & (d5 <= d6), c),                                                                      # C
        ((d3 >= 0) & (d4 <= d3), b),                                                                      # B
        ((d1 <= 0) & (d2 <= 0), a),                                                                       # A
    ]
    for mask, point in regions:
        out = np.where(mask[:, None], point, out)
    # a degenerate (zero-area) triangle whose point fell in the "face" region: best of its three edges
    in_face = ~np.any([mask for mask, _ in regions], axis=0)
    flat = in_face & (den <= 1e-12 * dot(ab, ab) * dot(ac, ac))
    if flat.any():
        cands = []
        for s, e in ((a, b), (b, c), (c, a)):
            se = (e - s)[flat]
            t = ratio(dot(p[flat] - s[flat], se), dot(se, se))
            cands.append(s[flat] + t * se)
        cands = np.stack(cands)
        best = np.argmin(np.linalg.norm(cands - p[flat], axis=2), axis=0)
        out[flat] = cands[best, np.arange(len(best))]
    return out


def _pair_distances(points, tri, pi, ti, out):
    """``out[pi] = min(out[pi], |points[pi] − closest point of triangle tri[ti]|)`` in chunks of pairs."""
    for s in range(0, len(ti), CHUNK_PAIRS):
        p, t = pi[s:s + CHUNK_PAIRS], ti[s:s + CHUNK_PAIRS]
        q = closest_points_on_triangles(points[p], tri[t, 0], tri[t, 1], tri[t, 2])
        np.minimum.at(out, p, np.linalg.norm(q - points[p], axis=1))


def _incident_faces(faces, V):
    """``(V, K)`` faces around each vertex, padded with −1."""
    f = np.repeat(np.arange(len(faces)), 3)
    v = faces.ravel()
    order = np.argsort(v, kind="stable")
    v, f = v[order], f[order]
    counts = np.bincount(v, minlength=V)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    table = np.full((V, max(1, counts.max())), -1, dtype=np.int64)
    table[v, np.arange(len(v)) - start[v]] = f
    return table


def _radius_bins(radius, ratio=2.0):
    """Triangle indices grouped so that radii within a group differ by at most ``ratio``: a list of
    ``(indices, max radius)``."""
    level = np.floor(np.log(np.maximum(radius, 1e-300) / max(radius.max(), 1e-300)) / np.log(ratio))
    level = np.maximum(level, -40)
    return [(np.flatnonzero(level == lv), radius[level == lv].max()) for lv in np.unique(level)]


def distance_to_surface(points, vertices, faces, knn=8):
    """Distance ``(N,)`` of each point ``(N, 3)`` to the nearest triangle of the mesh ``vertices (V, 3)``,
    ``faces (F, 3)`` (exact; see the module docstring).

    Pruning: the triangles around the nearest mesh vertex give an upper bound d (exact distances).  A
    triangle with centroid c and radius r (about c) can only be closer if ``|p − c| − r < d``.  Triangles
    are grouped by radius (within a factor 2); per group a k-d tree over the centroids returns the
    ``knn`` nearest centroids, of which those within ``d + r_max(group)`` are tested; points for which
    that list may be truncated (all ``knn`` within reach) get a full ball query.  Every pair that is
    not pruned is evaluated exactly."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise ValueError("distance_to_surface: the mesh has no triangles")
    N = len(points)
    used = np.unique(faces)
    _, nearest = cKDTree(vertices[used]).query(points)
    tri = vertices[faces]                                   # (F, 3, 3)
    around = _incident_faces(faces, len(vertices))[used[nearest]]          # (N, K)
    pi, k = np.nonzero(around >= 0)
    best = np.full(N, np.inf)
    _pair_distances(points, tri, pi, around[pi, k], best)
    centre = tri.mean(axis=1)
    radius = np.linalg.norm(tri - centre[:, None], axis=2).max(axis=1)
    for group, r_max in _radius_bins(radius):
        tree = cKDTree(centre[group])
        kk = min(knn, len(group))
        reach = best + r_max * (1 + 1e-9) + 1e-12
        dist, idx = tree.query(points, k=kk)
        dist, idx = dist.reshape(N, kk), idx.reshape(N, kk)
        hit = dist < reach[:, None]
        full = hit[:, -1] & (kk < len(group))               # maybe more than kk within reach
        hit[full] = False
        pi, col = np.nonzero(hit)
        ti = group[idx[pi, col]]
        keep = dist[pi, col] - radius[ti] < best[pi] + 1e-12
        _pair_distances(points, tri, pi[keep], ti[keep], best)
        rows = np.flatnonzero(full)
        if len(rows):
            lists = tree.query_ball_point(points[rows], reach[rows])
            counts = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(rows))
            ti = group[np.fromiter((i for x in lists for i in x), dtype=np.int64, count=int(counts.sum()))]
            _pair_distances(points, tri, np.repeat(rows, counts), ti, best)
    return best


def per_vertex_scan_distances(points, surfaces, faces):
    """``(M, N)``: distance of ``points[m, i]`` (``(M, N, 3)``) to the surface of frame m, vertices
    ``surfaces (M, V, 3)`` sharing triangles ``faces (F, 3)``.  For a registered sequence either side may be
    the scans: scan vertices to the posed model (what the learned rig's report and heat map use) or posed
    vertices to the scans."""
    points = np.asarray(points, dtype=np.float64)
    return np.stack([distance_to_surface(points[m], surfaces[m], faces) for m in range(len(points))])


def _median(x):
    return float(np.median(x)) if len(x) else float("nan")


def error_statistics(values) -> dict:
    """``{"mean", "std", "median", "mad", "iqr", "max", "count"}`` of the numbers ``values`` (any shape)."""
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    n = len(x)
    if n == 0:
        return {"mean": float("nan"), "std": float("nan"), "median": float("nan"), "mad": float("nan"),
                "iqr": float("nan"), "max": float("nan"), "count": 0}
    med = _median(x)
    half = n // 2
    q1, q3 = _median(x[:half]) if half else med, _median(x[n - half:]) if half else med
    return {"mean": float(x.mean()), "std": float(x.std()), "median": med,
            "mad": _median(np.abs(x - med)), "iqr": q3 - q1, "max": float(x[-1]), "count": n}
