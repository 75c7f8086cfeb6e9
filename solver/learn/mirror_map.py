"""Vertex mirror map of a mesh: every vertex's mirror image, found from the mesh topology, which does not
depend on the pose (dissertation (model-adaptive mocap) §3.2; docs/learn_rig_solver.md).

A triangulated quad mesh such as MakeHuman's is mirror symmetric in its quads (not its triangles: mirror-
image quads are split along either diagonal).  The triangles are merged back into quads
(:func:`polygons_of`); one quad and its mirror image, paired by their side and diagonal lengths
(:func:`_length_seeds`), seed a correspondence that :func:`propagate_mirror` extends over the mesh or
proves wrong.  Posed scans are too asymmetric for a symmetry plane to give the map, so a geometric map
(mutual nearest reflected vertices in the most symmetric shape) serves only meshes without such a
topology, and only where their geometry is exactly symmetric.

Maps are ``(V,)`` int64 arrays: ``m[v]`` is the mirror vertex of v, -1 where none is known; a complete map
is an involution (``m[m] = identity``).  Positions in metres.
"""
from itertools import islice

import numpy as np

from ..geometry.mesh_graph import edges_of
from ..geometry.neighbours import far_query_tree
from .symmetry import reflect, symmetry_planes

MIRROR_SCANS = 6            # at most this many shapes (rest first, then evenly spaced scans) are used
MIRROR_GEOMETRIC_TOL = 0.25  # geometric map: reflected vertex within this × median edge length
MIRROR_SEED_POLYGONS = 8    # topological map: seed quads (their mirror images found by lengths) ...
MIRROR_SIGNATURE_TOL = 0.01  # ... whose image quads have lengths within this fraction
MIRROR_TRIES = 200          # ... and at most this many propagations in all
MIRROR_EDGE_TOL = 0.05      # topological map: median relative difference of mirrored edges' mean lengths


def _paired_quads(f):
    """Quads ``(Q,4)`` when every two consecutive triangles of ``f (F,3)`` share an edge (in opposite
    directions): how a quad mesh is usually triangulated and written.  Otherwise None."""
    if len(f) == 0 or len(f) % 2:
        return None
    a, b = f[0::2], f[1::2]
    for r in range(3):                              # rotate the first triangle: (x0, x1, x2), x2 -> x0 shared
        x = np.roll(a, -r, axis=1)
        for s in range(3):
            y = np.roll(b, -s, axis=1)               # (x0, x2, y) is the second triangle
            hit = (y[:, 0] == x[:, 0]) & (y[:, 1] == x[:, 2])
            if r == 0 and s == 0:
                quads, found = np.zeros((len(a), 4), dtype=np.int64), np.zeros(len(a), dtype=bool)
            new = hit & ~found
            quads[new] = np.concatenate([x[new], y[new, 2:]], axis=1)
            found |= new
    return quads if found.all() else None


def polygons_of(faces, points):
    """Triangles merged back into the quads they were split from: consecutive triangle pairs when every
    pair shares an edge (:func:`_paired_quads`; MakeHuman), else two triangles sharing an edge that is
    the longest of both (the quad's diagonal; lengths averaged over ``points (M,V,3)``).  A triangulated
    quad mesh splits mirror-image quads along either diagonal, so only its quads are mirror symmetric.
    Returns a list of vertex tuples (3 or 4 vertices, orientation kept)."""
    f = np.asarray(faces, dtype=np.int64)
    quads = _paired_quads(f)
    if quads is not None:
        return [tuple(q) for q in quads.tolist()]
    pts = np.asarray(points, dtype=np.float64)
    pts = pts if pts.ndim == 3 else pts[None]
    nxt = f[:, [1, 2, 0]]
    length = np.mean(np.linalg.norm(pts[:, nxt] - pts[:, f], axis=3), axis=0)      # edge (f_i, f_i+1)
    r = np.argmax(length, axis=1)                                                  # longest: f_r -> f_r+1
    tri = np.take_along_axis(f, (r[:, None] + np.array([2, 0, 1])) % 3, axis=1)   # (x0, x1, x2), x2 -> x0 longest
    V = int(f.max()) + 1 if len(f) else 0
    owner = {}
    for i, (x0, x1, x2) in enumerate(tri.tolist()):
        owner.setdefault(x2 * V + x0, []).append(i)
    done = np.zeros(len(f), dtype=bool)
    polys = []
    for i, (x0, x1, x2) in enumerate(tri.tolist()):
        if done[i]:
            continue
        other = owner.get(x0 * V + x2, [])
        j = other[0] if len(other) == 1 and len(owner[x2 * V + x0]) == 1 else -1
        if j >= 0 and not done[j]:
            polys.append((x0, x1, x2, int(tri[j, 1])))                             # j is (x2, y, x0)
            done[j] = True
        else:
            polys.append((x0, x1, x2))
        done[i] = True
    return polys


def _halfedges(polys, V):
    """``{p·V + q: (the polygon's other vertices after q, in order)}`` for every directed edge (p, q) of
    the polygons; directed edges used by more than one polygon (non-manifold or inconsistently oriented
    meshes) are left out."""
    H, bad = {}, set()
    for poly in polys:
        n = len(poly)
        for i in range(n):
            key = poly[i] * V + poly[(i + 1) % n]
            if key in H:
                bad.add(key)
            H[key] = tuple(poly[(i + 2 + j) % n] for j in range(n - 2))
    for key in bad:
        del H[key]
    return H


def propagate_mirror(H, V, seed):
    """Extend a mirror correspondence of one polygon over the mesh.  A reflection reverses orientation,
    so polygon (p, q, x1..xj) maps to (m(p), m(xj), .., m(x1), m(q)): the vertices after directed edge
    (m(q), m(p)) are m(xj), .., m(x1).  From ``seed`` = ((vertices), (their images)) every polygon
    reachable over manifold edges is mapped, depth first (``H``: :func:`_halfedges`).  Returns the map
    ``(V,)`` int64, or None when two polygons disagree on a vertex's image (or a polygon's image has
    another vertex count), some vertex is not reached, or the map is not an involution (m(m(v)) = v):
    the mesh topology is not mirror symmetric, or the seed was wrong."""
    m = [-1] * V
    for v, w in zip(*seed):
        if m[v] not in (-1, w):
            return None
        m[v] = w
    src = list(seed[0])
    stack = [(p, q) for p in src for q in src if p != q]
    seen = set()
    while stack:
        p, q = stack.pop()
        key = p * V + q
        if key in seen:
            continue
        seen.add(key)
        xs = H.get(key)
        ys = H.get(m[q] * V + m[p])
        if xs is None or ys is None:
            continue
        if len(xs) != len(ys):
            return None
        for x, y in zip(xs, reversed(ys)):
            if m[x] < 0:
                m[x] = y
            elif m[x] != y:
                return None
        ring = (p, q) + xs
        n = len(ring)
        stack += [(ring[(i + 1) % n], ring[i]) for i in range(n)] + [(ring[i], ring[(i + 1) % n]) for i in range(n)]
    m = np.array(m, dtype=np.int64)
    if m.min() < 0 or not np.array_equal(m[m], np.arange(V)):
        return None
    return m


def _length_seeds(polys, shapes, count=MIRROR_SEED_POLYGONS, tol=MIRROR_SIGNATURE_TOL):
    """Pose-independent seed correspondences for :func:`propagate_mirror`: a mirror map keeps lengths, so a
    quad's image is a quad with the same side and diagonal lengths in reversed order.  Lengths are
    medians over ``shapes (S,V,3)`` (far from joints they do not change with the pose).  For ``count``
    quads with the least length variation over the shapes (spread over the mesh), every quad and
    orientation-reversing rotation whose 6 lengths agree within ``tol`` (relative, largest difference) is
    a hypothesis.  Yields ``(quad, images of its vertices)``, best agreement first within each quad."""
    quads = np.array([q for q in polys if len(q) == 4], dtype=np.int64)
    if len(quads) < 2:
        return
    pairs = [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2), (1, 3)]
    L = np.stack([np.linalg.norm(shapes[:, quads[:, i]] - shapes[:, quads[:, j]], axis=2) for i, j in pairs], 2)
    med = np.median(L, axis=0)                                             # (Q, 6)
    spread = np.max((L.max(axis=0) - L.min(axis=0)) / np.maximum(med, 1e-300), axis=1)
    order = np.argsort(spread, kind="stable")
    picks = order[np.linspace(0, max(len(order) // 4 - 1, 0), count).astype(np.int64)]
    # lengths of every quad re-listed as the image of quad p under rotation r: side i of p = side
    # (r - i - 1) mod 4 of q, diagonal (0, 2) of p = diagonal r mod 2 of q, (1, 3) -> (r - 1) mod 2
    images = []
    for r in range(4):
        idx = [(r - i - 1) % 4 for i in range(4)] + [4 + r % 2, 4 + (r - 1) % 2]
        images.append(med[:, idx])
    images = np.stack(images, 1)                                           # (Q, 4, 6)
    for p in picks:
        diff = np.max(np.abs(images - med[p]) / np.maximum(med[p], 1e-300), axis=2)     # (Q, 4)
        qs, rs = np.nonzero(diff <= tol)
        for j in np.argsort(diff[qs, rs], kind="stable"):
            q, r = quads[qs[j]], rs[j]
            yield quads[p].tolist(), [int(q[(r - i) % 4]) for i in range(4)]


def mirror_map(rest, scans, faces, max_scans=MIRROR_SCANS):
    """Vertex mirror map ``(V,)`` int64 (each vertex → its mirror image; -1: none known) or None, from
    ``rest (V,3)``, ``scans (M,V,3)`` and ``faces (F,3)``: the topological map (:func:`topological_map`)
    of the rest and up to ``max_scans`` − 1 evenly spaced scans, else the geometric one
    (:func:`geometric_map`).  None when neither finds anything (no symmetry plane, or no vertex
    matched)."""
    rest = np.asarray(rest, dtype=np.float64)
    scans = np.asarray(scans, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    step = max(1, int(np.ceil(len(scans) / max(1, max_scans - 1))))
    shapes = np.concatenate([rest[None], scans[::step][:max_scans - 1]])          # (S, V, 3)
    m = topological_map(shapes, faces)
    return m if m is not None else geometric_map(shapes, faces)


def edge_lengths(shapes, edges):
    """Length ``(E,)`` of every edge ``(E,2)``, mean over ``shapes (S,V,3)``."""
    return np.mean(np.linalg.norm(shapes[:, edges[:, 0]] - shapes[:, edges[:, 1]], axis=2), axis=0)


def topological_map(shapes, faces):
    """Mirror map of a mesh whose polygon topology is mirror symmetric (as MakeHuman's), or None.  Seed
    correspondences of one quad (:func:`_length_seeds`, lengths as medians over ``shapes (S,V,3)``) are
    extended over the mesh by :func:`propagate_mirror`, which fails on a wrong seed; the first complete,
    consistent involution that also keeps the edges' mean lengths (median relative difference within
    MIRROR_EDGE_TOL: a regular mesh has other automorphisms, e.g. a grid flipped along the wrong axis)
    is returned; at most MIRROR_TRIES seeds."""
    V = shapes.shape[1]
    polys = polygons_of(faces, shapes)
    H = _halfedges(polys, V)
    e = edges_of(faces)
    mean_length = edge_lengths(shapes, e)
    for poly, img in islice(_length_seeds(polys, shapes), MIRROR_TRIES):
        m = propagate_mirror(H, V, (poly, img))
        if m is None:
            continue
        other = edge_lengths(shapes, m[e])
        if np.median(np.abs(mean_length - other) / np.maximum(np.maximum(mean_length, other), 1e-300)) \
                <= MIRROR_EDGE_TOL:
            return m
    return None


def geometric_map(shapes, faces):
    """Mirror map from geometry (meshes without a topological map, e.g. non-manifold ones), or None: in the
    most symmetric of ``shapes (S,V,3)`` (best :func:`solver.learn.symmetry.symmetry_planes` score), the
    mutual reflected nearest-vertex matches within MIRROR_GEOMETRIC_TOL of the median rest edge length
    (exactly symmetric geometry only; elsewhere -1)."""
    V = shapes.shape[1]
    e = edges_of(faces)
    rest = shapes[0]
    edge = float(np.median(np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1))) if len(e) else 0.0
    best = None
    for pts in shapes:
        planes = symmetry_planes(pts)
        if not planes:
            continue
        n, d, score = planes[0]
        dist, idx = far_query_tree(pts).query(reflect(pts, n, d))
        mutual = idx[idx] == np.arange(V)
        if best is None or score < best[0]:
            best = (score, np.where(mutual & (dist <= MIRROR_GEOMETRIC_TOL * edge), idx, -1))
    if best is None or best[1].max() < 0:
        return None
    return best[1]
