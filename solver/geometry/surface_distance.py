"""Exact point-to-surface distances of triangle meshes and the error statistics of the model-adaptive mocap
dissertation §6.1.

* :func:`closest_points_on_triangles` — the closest point of triangle (a, b, c) to p, per row, by the
  Voronoi-region test (vertex, edge or face region; Ericson, *Real-Time Collision Detection* §5.1.5,
  written from the description), vectorised over rows.
* :func:`distance_to_surface` — distance of every query point to the nearest triangle of a mesh,
  exactly (up to rounding):

  1. upper bound u per point: the exact distance to the triangle with the nearest centroid;
  2. candidates: a triangle can only be closer than u if its bounding sphere (centroid c, radius r
     about c) comes within u of the point, and if the disc of radius r about c in the triangle's plane
     does.  The sphere test runs inside ``cKDTree.sparse_distance_matrix`` between a tree of points
     (one per group of similar u) and a tree of centroids (one per group of similar r), with the
     largest u + r of the two groups as radius; the exact per-pair sphere and disc tests follow;
  3. exact distances to the candidates (a vectorised kernel on precomputed triangle frames: height
     over the plane, in-plane distance to the three edges; the region test for thin triangles).

  One k-d tree over all centroids would need the largest triangle radius as search margin for every
  point (MakeHuman radii range 1.8-50 mm: ~1,000-2,500 centroids per point), hence the groups
  (docs/evaluation.md, "Metrics", has the timings).
* :func:`per_vertex_scan_distances` — per frame m, the distance of points m to surface m, ``(M, N)``; the
  heat map of a learned rig is its mean over m of scan vertex v to the posed model's surface.
* :func:`error_statistics` — mean, std, median, MAD = median |x − median|, IQR = Q3 − Q1 and max.
  Q1/Q3 are the medians of the lower/upper halves (the middle element excluded for odd n), as the
  dissertation defines them.

Units: those of the input (metres in Articula); :func:`error_statistics` only summarises numbers.
"""
import numpy as np
from scipy.spatial import cKDTree

from .. import parallel

RADIUS_RATIO = 1.5      # triangle radii within one centroid tree differ by at most this factor
BOUND_RATIO = 2.0       # upper bounds within one point tree differ by at most this factor
SLACK = 1e-9            # pruning margin, relative to the coordinate scale (absorbs rounding)
THIN = 1e-2             # |AB × AC| <= THIN · longest edge²: plane ill-conditioned, use the region test
CHUNK_PAIRS = 4_000_000  # point/centroid pairs held at once (only far points come near it)
FAR = 4.0               # bounds beyond FAR × largest triangle radius: per-point ball queries
BATCH_POINTS = 20_000   # per_vertex_scan_distances measures frames with fewer points several at a time


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
    ab2, ac2, bc2 = dot(ab, ab), dot(ac, ac), dot(c - b, c - b)    # a zero-length edge has no region
    regions = [
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0) & (bc2 > 0), b + ratio(d4 - d3, (d4 - d3) + (d5 - d6)) * (c - b)),  # BC
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0) & (ac2 > 0), a + ratio(d2, d2 - d6) * ac),                                 # AC
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0) & (ab2 > 0), a + ratio(d1, d1 - d3) * ab),                                 # AB
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


def _cross(x, y):
    """Row-wise cross products of ``(..., 3)`` arrays (cheaper than ``np.cross`` for many short rows)."""
    return np.stack([x[..., 1] * y[..., 2] - x[..., 2] * y[..., 1],
                     x[..., 2] * y[..., 0] - x[..., 0] * y[..., 2],
                     x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]], axis=-1)


def _triangle_frames(tri):
    """Per triangle ``tri (F,3,3)``: ``(rows (F,3,7), offsets (F,7), edge lengths (F,3), thin (F,))``.

    The 7 columns of rows: unit normal n, in-plane outward edge normals m_k and unit edge directions
    e_k of the edges AB, BC, CA (k = 0, 1, 2, starting at vertex k); offsets = ``column · (start of
    its edge − A)``, so that ``(p − A) · rows − offsets`` = (height over the plane, outward distances to
    the three edge lines, positions along the three edges).  Thin triangles (|AB × AC| <= THIN ·
    longest edge², whose normal would carry a rounding error ~1e-16 / THIN) are flagged, zero rows."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    edge = np.stack([b - a, c - b, a - c], axis=1)
    length = np.sqrt(np.einsum("fki,fki->fk", edge, edge))
    cross = _cross(edge[:, 0], c - a)
    area2 = np.sqrt(np.einsum("fi,fi->f", cross, cross))
    thin = area2 <= THIN * length.max(axis=1) ** 2
    normal = cross / np.where(thin, 1.0, area2)[:, None]
    normal[thin] = 0.0
    along = edge / np.where(length > 0, length, 1.0)[..., None]
    out = _cross(along, normal[:, None, :])
    start = np.stack([np.zeros_like(a), b - a, c - a], axis=1)
    offsets = np.zeros((len(tri), 7))
    offsets[:, 1:4] = np.einsum("fki,fki->fk", out, start)
    offsets[:, 4:7] = np.einsum("fki,fki->fk", along, start)
    rows = np.concatenate([normal[:, None], out, along], axis=1).transpose(0, 2, 1)
    return np.ascontiguousarray(rows), offsets, length, thin


def _pair_distances(points, tri, frames, pi, ti):
    """Exact distances ``(n,)`` of ``points[pi]`` to triangles ``tri[ti]`` (frames from
    :func:`_triangle_frames`): sqrt(height² + in-plane distance²), the in-plane distance being 0 when the
    foot lies inside all three edges, else the smallest distance to the three edge segments.  Thin
    triangles go through :func:`closest_points_on_triangles`."""
    rows, offsets, length, thin = frames
    w = np.take(points, pi, axis=0) - np.take(tri[:, 0], ti, axis=0)
    y = np.einsum("njk,nj->nk", np.take(rows, ti, axis=0), w) - np.take(offsets, ti, axis=0)
    height, out, pos = y[:, 0], y[:, 1:4], y[:, 4:7]
    beyond = pos - np.clip(pos, 0.0, np.take(length, ti, axis=0))
    inplane = np.min(out * out + beyond * beyond, axis=1)
    inplane[np.all(out <= 0.0, axis=1)] = 0.0
    dist = np.sqrt(height * height + inplane)
    bad = np.take(thin, ti)
    if bad.any():
        p, t = pi[bad], ti[bad]
        q = closest_points_on_triangles(points[p], tri[t, 0], tri[t, 1], tri[t, 2])
        dist[bad] = np.linalg.norm(q - points[p], axis=1)
    return dist


def _tree(x):
    """k-d tree with sliding-midpoint splits and unshrunk node boxes (faster for these queries; docs/evaluation.md)."""
    return cKDTree(x, compact_nodes=False, balanced_tree=False)


def _groups(values, floor, ratio):
    """Index arrays of ``values`` grouped so that a group's values lie within ``ratio`` of each other
    (values below ``floor`` count as ``floor``)."""
    level = np.floor(np.log(np.maximum(values, floor) / floor) / np.log(ratio)).astype(np.int64)
    order = np.argsort(level, kind="stable")
    cuts = np.flatnonzero(np.diff(level[order])) + 1
    return np.split(order, cuts)


def _distances(points, tri, frames, pi, ti, tol):
    """:func:`_pair_distances`; below ``tol`` the distance to the nearest corner if smaller (rounding:
    exactly 0 for a point on a vertex)."""
    dist = _pair_distances(points, tri, frames, pi, ti)
    near = np.flatnonzero(dist < tol)
    if len(near):
        corner = np.take(tri, ti[near], axis=0) - np.take(points, pi[near], axis=0)[:, None]
        corner = np.sqrt(np.einsum("nki,nki->nk", corner, corner).min(axis=1))
        dist[near] = np.minimum(dist[near], corner)
    return dist


def _nearest_centroid_bounds(points, tri, centre, frames, tol):
    """Upper bounds ``u (N,)``: the exact distance to the triangle with the nearest centroid, and those
    triangles ``(N,)``."""
    _, nearest = _tree(centre).query(points)
    return _distances(points, tri, frames, np.arange(len(points)), nearest, tol), nearest


def _pairs_within(points, rows, ptree, tree, radius):
    """``(rows index (n,), tree index (n,), distance (n,))`` of the pairs of ``points[rows]`` (k-d tree
    ``ptree``) and the points of ``tree`` closer than ``radius``, found by
    ``cKDTree.sparse_distance_matrix``; when a sample suggests more than ``CHUNK_PAIRS`` pairs (far
    points, huge bounds), per chunk of rows holding at most about that many."""
    sample = np.take(points, rows[:: max(1, len(rows) // 32)], axis=0)
    if tree.query_ball_point(sample, radius, return_length=True).mean() * len(rows) <= CHUNK_PAIRS / 4:
        pairs = ptree.sparse_distance_matrix(tree, radius, output_type="ndarray")
        return np.take(rows, pairs["i"]), pairs["j"], pairs["v"]
    counts = tree.query_ball_point(np.take(points, rows, axis=0), radius, return_length=True)
    chunk = np.cumsum(counts) // CHUNK_PAIRS
    out = []
    for part in np.split(rows, np.flatnonzero(np.diff(chunk)) + 1):
        pairs = _tree(np.take(points, part, axis=0)).sparse_distance_matrix(tree, radius, output_type="ndarray")
        out.append((np.take(part, pairs["i"]), pairs["j"], pairs["v"]))
    return tuple(np.concatenate(x) for x in zip(*out))


def _pairs_in_balls(points, rows, tree, radii):
    """Like :func:`_pairs_within` with a radius per point ``radii (len(rows),)``, by ball queries (for
    points far from the mesh, whose bounds differ by more than the triangles' size)."""
    x = np.take(points, rows, axis=0)
    lists = tree.query_ball_point(x, radii)
    counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(rows))
    j = np.fromiter((k for idx in lists for k in idx), dtype=np.int64, count=int(counts.sum()))
    i = np.repeat(np.arange(len(rows)), counts)
    return np.take(rows, i), j, np.linalg.norm(np.take(x, i, axis=0) - np.take(tree.data, j, axis=0), axis=1)


def _sphere_and_disc(points, reach, i, t, d, radius, normal, plane):
    """Of the pairs (point i, triangle t) with centroid distance ``d``, those whose bounding sphere and
    bounding disc (radius about the centroid, in the plane ``x·normal = plane``) come within ``reach[i]``."""
    r = np.take(radius, t)
    keep = d - r <= np.take(reach, i)
    i, t, d, r = i[keep], t[keep], d[keep], r[keep]
    h = np.einsum("ni,ni->n", np.take(normal, t, axis=0), np.take(points, i, axis=0)) - np.take(plane, t)
    gap = np.maximum(np.sqrt(np.maximum(d * d - h * h, 0.0)) - r, 0.0)
    keep = h * h + gap * gap <= np.take(reach, i) ** 2
    return i[keep], t[keep]


def _candidates(points, reach, centre, radius, normal, tol):
    """Pairs ``(pi, ti)`` of points and triangles that may lie within ``reach (N,)`` of the point: the
    bounding sphere (``centre``, ``radius``) and the disc of that radius in the triangle's plane
    (``normal``, zero for thin triangles) come within reach.  Centroid trees per group of radii
    within RADIUS_RATIO (radii below the 10th percentile count as that), point trees per group of
    reaches within BOUND_RATIO (below the 25th percentile count as that)."""
    rmax = radius.max()
    small = max(np.percentile(radius, 10), 1e-12 * rmax, 1e-300)
    bins = _groups(rmax / np.maximum(radius, small), 1.0, RADIUS_RATIO)
    trees = [(_tree(np.take(centre, b, axis=0)), b, np.take(radius, b).max()) for b in bins]
    plane = np.einsum("fi,fi->f", normal, centre)
    found = []
    for rows in _groups(reach, max(np.percentile(reach, 25), tol, 1e-300), BOUND_RATIO):
        reach_rows = np.take(reach, rows).max()
        far = reach_rows > FAR * rmax
        ptree = None if far else _tree(np.take(points, rows, axis=0))
        for tree, members, r_bin in trees:
            if far:
                i, j, d = _pairs_in_balls(points, rows, tree, np.take(reach, rows) + r_bin + tol)
            else:
                i, j, d = _pairs_within(points, rows, ptree, tree, reach_rows + r_bin + tol)
            found.append(_sphere_and_disc(points, reach, i, np.take(members, j), d, radius, normal, plane))
    return np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found])


def distance_to_surface(points, vertices, faces):
    """Distance ``(N,)`` of each point ``(N, 3)`` to the nearest triangle of the mesh ``vertices (V, 3)``,
    ``faces (F, 3)``, exact up to rounding (see the module docstring for the pruning).  Every triangle
    within the upper bound u of a point passes both the sphere and the disc test, so it is evaluated:
    the minimum over evaluated triangles is the minimum over all."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise ValueError("distance_to_surface: the mesh has no triangles")
    if len(points) == 0:
        return np.zeros(0)
    tri = np.take(vertices, faces, axis=0)                             # (F, 3, 3)
    centre = tri.mean(axis=1)
    off = tri - centre[:, None]
    radius = np.sqrt(np.einsum("fki,fki->fk", off, off).max(axis=1))
    frames = _triangle_frames(tri)
    tol = SLACK * (np.abs(tri).max() + np.abs(points).max() + radius.max())
    best, nearest = _nearest_centroid_bounds(points, tri, centre, frames, tol)
    pi, ti = _candidates(points, best + tol, centre, radius, frames[0][:, :, 0], tol)
    new = ti != np.take(nearest, pi)                                    # not evaluated yet
    pi, ti = pi[new], ti[new]
    np.minimum.at(best, pi, _distances(points, tri, frames, pi, ti, tol))
    return best


def per_vertex_scan_distances(points, surfaces, faces, progress=None):
    """``(M, N)``: distance of ``points[m, i]`` (``(M, N, 3)``) to the surface of frame m, vertices
    ``surfaces (M, V, 3)`` sharing triangles ``faces (F, 3)``.  For a registered sequence either side may be
    the scans: scan vertices to the posed model (what the learned rig's report and heat map use) or posed
    vertices to the scans.

    Small frames are measured several at a time (:func:`_side_by_side`, at least ``BATCH_POINTS`` points
    per call), so that the searches' fixed costs are paid per batch instead of per frame; the batches
    go to the solver's threads (the distances equal the frame-by-frame ones to rounding).
    progress(fraction): with it the batches go to the threads one at a time and it is called in the
    calling thread as each is done, in order (:func:`parallel.map_in_order`; the same distances); it
    may raise (e.g. ``Cancelled``): the batches not started are dropped."""
    points = np.asarray(points, dtype=np.float64)
    surfaces = np.asarray(surfaces, dtype=np.float64)
    M, N = points.shape[:2]
    out = np.empty((M, N))
    per_batch = max(1, BATCH_POINTS // max(N, 1))
    spacing = _frame_spacing(points, surfaces)

    def batches(starts):                                # a piece of batches per solver thread
        for m0 in starts:
            sl = slice(m0, min(M, m0 + per_batch))
            out[sl] = distance_to_surface(*_side_by_side(points[sl], surfaces[sl], faces, spacing)
                                          ).reshape(sl.stop - sl.start, N)

    starts = np.arange(0, M, per_batch)
    if progress is None:
        parallel.map_pieces(batches, [starts[idx] for idx in parallel.split(len(starts))])
    else:
        parallel.map_in_order(batches, [[m0] for m0 in starts], parallel.workers(),
                              lambda i, _: progress((i + 1) / len(starts)))
    return out


def _frame_spacing(points, surfaces):
    """Offset between frames placed side by side: 4× the diagonal of the box holding every point and
    surface vertex of every frame (1 if that is 0)."""
    if points.size == 0 or surfaces.size == 0:
        return 1.0
    lo = np.minimum(points.min(axis=(0, 1)), surfaces.min(axis=(0, 1)))
    hi = np.maximum(points.max(axis=(0, 1)), surfaces.max(axis=(0, 1)))
    diag = float(np.linalg.norm(hi - lo))
    return 4.0 * diag if diag > 0 else 1.0


def _side_by_side(points, surfaces, faces, spacing):
    """``(points (k N, 3), vertices (k V, 3), faces (k F, 3))`` of k frames laid out along x, frame j moved
    by ``j · spacing``.  With spacing ≥ 4 × the data's diameter D, a point is at least 3D from every
    other frame's triangles and at most D from its own, so its nearest triangle (and every candidate of
    :func:`distance_to_surface`, whose bounds stay below 2D) is in its own frame: the distances are
    those of the frames one by one, up to the rounding of the shifted coordinates."""
    k, V = surfaces.shape[:2]
    shift = np.zeros((k, 1, 3))
    shift[:, 0, 0] = spacing * np.arange(k)
    tris = (np.asarray(faces, dtype=np.int64)[None] + V * np.arange(k)[:, None, None]).reshape(-1, 3)
    return (points + shift).reshape(-1, 3), (surfaces + shift).reshape(-1, 3), tris


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


FOOT_CANDIDATES = 4     # nearest centroids tried first for a foot point; the rest by an exact ball query
FOOT_TOL = 1e-12        # a candidate within FOOT_TOL x (coordinate scale of the point) of the distance is the foot


def closest_on_surface(points, vertices, faces):
    """``(distances (N,), feet (N, 3), triangles (N,))``: each point's exact distance to the mesh
    (:func:`distance_to_surface`), a closest point and a triangle holding it (ties: any); inputs
    ``(N, 3)``, ``(V, 3)``, ``(F, 3)`` int64, unchecked.  The triangles of the ``FOOT_CANDIDATES``
    nearest centroids are tried first; a point none of them reaches within rounding of its exact
    distance d gets every triangle whose centroid lies within d + (largest centroid-to-corner radius)."""
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
