"""The body a tracker fits: a model evaluated exactly (hybrid skin) with its pose Jacobian on the
vertices a fit needs, and the closest points of its posed surface.

Parameters of one frame (``P = 3 + 3B``): the root translation (world metres, additive) and one
rotation increment per bone (rotation vector in the bone's local axes, applied on the right:
``q_b <- q_b exp(delta_b)``), the layout of :func:`solver.rig.jacobians.pose_layout` without the scale
column; the subject's scale stays what the pose says.  Shapes: posed vertices ``(V, 3)``, Jacobians
``(n, 3, P)``.
"""
from __future__ import annotations

import functools

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from ..errors import ArticulaInputError
from ..parallel import map_pieces, workers
from ..rig.jacobians import apply_pose_increment, pose_jacobian, sorted_jacobian
from ..rig.model import Model, Poses
from ..rig.skinning import AnchorGroups, hybrid_skin

NEAREST = 2                  # vertices whose triangles are searched for a closest point
WIDE = 16                    # ... for a query EXACT_BEYOND..EXACT_WITHIN (m) from those triangles
EXACT_BEYOND = 0.003
EXACT_WITHIN = 0.1
EXACT_SHARE = 0.1            # ... and then the mesh's exact closest point while at most this share is that far
JACOBIAN_REUSE_RAD = 0.08    # a vertex Jacobian serves poses this close (per bone, radians)
BOUND_SLACK = 1e-9          # a triangle is skipped only when provably farther than needed by this much (m)
PIECE = 1000                 # closest-point queries per thread at least


class Body:
    """A model ready for tracking: anchor groups, the one-ring of every vertex, parameter layout."""

    def __init__(self, model: Model):
        self.model = model
        self.groups = AnchorGroups(model)
        self.num_bones = model.skeleton.num_bones
        self.size = 3 + 3 * self.num_bones
        self.columns = np.r_[0:3, 4:4 + 3 * self.num_bones]     # of the rig's full layout (no scale)
        self.pieces = {"t": 0, **{("rot", b): 3 + 3 * b for b in range(self.num_bones)}}   # the same, by piece
        self.faces = np.asarray(model.faces, dtype=np.int64)
        self.ring = one_ring(self.faces, model.num_vertices)
        self._jacobians = {}                                           # slot -> (pose, J float32)

    def jacobian_near(self, pose: Poses, vertices, slot=0, tolerance: float = JACOBIAN_REUSE_RAD) -> np.ndarray:
        """``(n, 3, P)`` derivatives of ``vertices`` taken from one evaluation of every vertex's Jacobian
        at a pose within ``tolerance`` radians (per bone) of ``pose``, evaluated anew when none is;
        ``slot`` keeps one such evaluation per frame of a window.  Why: a fit moves the pose by little
        between its later iterations, and a Jacobian a few hundredths of a radian old changes only the
        Gauss–Newton steps, not the residuals, so not the pose the fit converges to."""
        rows = self.groups.inverse[np.asarray(vertices, dtype=np.int64)]
        return self._held(pose, slot, tolerance)[rows].astype(np.float64)

    def combined_jacobian(self, pose: Poses, vertices, coefficients, slot=0) -> np.ndarray:
        """``(K, P)`` = ``sum_c coefficients[k, c] . J(vertices[k, c])``: rows of held vertex Jacobians
        (:meth:`jacobian_near`) combined by ``coefficients (K, C, 3)`` in single precision (what a
        Gauss–Newton step needs), returned in double."""
        J = self._held(pose, slot, JACOBIAN_REUSE_RAD)                          # (V, 3, P), anchor order
        K, C = coefficients.shape[:2]
        rows = self.groups.inverse[np.asarray(vertices, dtype=np.int64).reshape(K, C, 1)]
        columns = (3 * rows + np.arange(3)).ravel()
        combine = csr_matrix((coefficients.astype(np.float32).ravel(), columns, np.arange(0, 3 * C * K + 1, 3 * C)),
                             shape=(K, J.shape[0] * 3))       # one sparse row per combination: no gathered copy
        return np.asarray(combine @ J.reshape(-1, J.shape[2]), dtype=np.float64)

    def _held(self, pose, slot, tolerance):
        held = self._jacobians.get(slot)
        if held is None or _turned(held[0], pose) > tolerance:
            J = sorted_jacobian(self.model, pose, self.pieces, self.size, self.groups, dtype=np.float32)[1][0]
            held = self._jacobians[slot] = (pose, J)
        return held[1]

    def forget(self, keep=()) -> None:
        """Drop the held Jacobians (memory: V x 3 x P float32 each) but those of the slots ``keep``."""
        for slot in [s for s in self._jacobians if s not in keep]:
            self.release(slot)

    def release(self, slot) -> None:
        """Drop the held Jacobian of ``slot`` (if any)."""
        self._jacobians.pop(slot, None)

    def held_pose(self, slot=0):
        """The pose ``slot``'s held Jacobian was evaluated at, or None.  With :meth:`hold` a run that
        continues another's repeats its steps exactly (:mod:`solver.track.trail`)."""
        held = self._jacobians.get(slot)
        return None if held is None else held[0]

    def hold(self, pose: Poses, slot=0) -> None:
        """Evaluate and hold ``slot``'s Jacobian at ``pose`` (what :meth:`jacobian_near` would hold)."""
        self.release(slot)
        self._held(pose, slot, 0.0)

    def holds_at(self, slot, pose: Poses) -> bool:
        """Whether ``slot``'s held Jacobian was evaluated at exactly ``pose``."""
        held = self.held_pose(slot)
        return held is not None and all(np.array_equal(a, b) for a, b in zip(
            (held.rotations, held.translations, held.scales), (pose.rotations, pose.translations, pose.scales)))

    def pose(self, pose: Poses) -> np.ndarray:
        """Posed vertices ``(V, 3)`` of one frame."""
        return hybrid_skin(self.model, pose, self.groups)[0]

    def jacobian(self, pose: Poses, vertices) -> np.ndarray:
        """``(n, 3, P)`` derivatives of the posed ``vertices`` (n,) by the frame's parameters."""
        vertices = np.asarray(vertices, dtype=np.int64)
        m = self.model
        sub = Model(m.rest_vertices[vertices], np.zeros((0, 3), np.int32), m.skeleton, m.anchor[vertices],
                    m.twist_weights[vertices], m.swing_weights[vertices])
        _, J = pose_jacobian(sub, pose, AnchorGroups(sub))
        return J[0][..., self.columns]

    def moved(self, pose: Poses, step) -> Poses:
        """The pose after the increment ``step`` (P,)."""
        full = np.zeros((1, 4 + 3 * self.num_bones))
        full[0, self.columns] = step
        return apply_pose_increment(pose, full)

    def surface(self, posed) -> "Surface":
        """The posed surface's closest-point queries."""
        return Surface(posed, self.faces, self.ring)


def _turned(a: Poses, b: Poses) -> float:
    """Largest rotation angle (radians) between the bones of two one-frame poses."""
    dot = np.abs(np.sum(a.rotations[0] * b.rotations[0], axis=1))
    return float(2.0 * np.arccos(np.clip(dot.min(), 0.0, 1.0)))


class Surface:
    """Closest points on a posed mesh: nearest vertex by a k-d tree, then the closest point on the
    triangles around it (exact point-triangle distance, edges and corners included)."""

    def __init__(self, vertices, faces, ring):
        self.vertices, self.faces, self.ring = vertices, faces, ring
        self.tree = cKDTree(vertices)
        a, b, c = (vertices[faces[:, k]] for k in range(3))
        self.corner, self.ab, self.ac = a, b - a, c - a
        self.gram = np.stack([_dot(self.ab, self.ab), _dot(self.ab, self.ac), _dot(self.ac, self.ac)], axis=1)
        n = np.cross(self.ab, self.ac)
        self.face_normals = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    @functools.cached_property
    def _longest(self):
        """``(F,)`` each triangle's longest edge (m): only the exact pass needs them."""
        bc = self.ac - self.ab
        return np.sqrt(np.max([_dot(self.ab, self.ab), _dot(bc, bc), _dot(self.ac, self.ac)], axis=0))

    def closest(self, queries):
        """``(face (Q,), barycentric (Q, 3), foot (Q, 3), vertex (Q,))`` of each query ``(Q, 3)``: the
        closest point on the triangles around its ``NEAREST`` nearest vertices (the nearest vertex
        alone misses the closest triangle where a long triangle's corners are all far), for queries
        ``EXACT_BEYOND``..``EXACT_WITHIN`` off those around its ``WIDE`` nearest, and then over the
        triangles that search can have missed (:meth:`_missed`)."""
        if len(queries) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64)
        face, bary, foot, dist, near, _ = self._rings(queries, NEAREST)
        far = np.flatnonzero((dist > EXACT_BEYOND) & (dist < EXACT_WITHIN))
        if len(far):
            f2, b2, p2, d2, _, reach = self._rings(queries[far], WIDE, dist[far])
            better = d2 < dist[far]
            rows = far[better]
            face[rows], bary[rows], foot[rows], dist[rows] = f2[better], b2[better], p2[better], d2[better]
            self._missed(queries, far, dist, reach, face, bary, foot)
        return face, bary, foot, near

    def _missed(self, queries, rows, dist, reach, face, bary, foot):
        """The ring search's answers for ``rows`` made exact, in place, while they are at most
        ``EXACT_SHARE`` of the queries (a converging fit).  A closer triangle none of whose corners was
        searched (all at least ``reach`` from the query) holds the closer foot p with its corners outside
        the ball of radius ``reach``, so its longest edge is at least ``sqrt(3 (reach^2 - dist^2))`` (an
        edge subtending 120 degrees or more at p): only triangles that long are searched, and of those
        only the ones whose bounding sphere (centroid, farthest corner) comes within ``dist``."""
        longest = self._longest
        need = np.sqrt(3.0 * np.maximum(reach ** 2 - dist[rows] ** 2, 0.0))
        keep = need <= longest.max()
        rows, need = rows[keep], need[keep]
        if not len(rows) or len(rows) > EXACT_SHARE * len(queries):
            return
        subset = np.flatnonzero(longest >= need.min())
        subset = subset[np.argsort(-longest[subset], kind="stable")]         # longest first, ties by index
        edge = longest[subset]
        corners = self.vertices[self.faces[subset]]                                # (S, 3, 3)
        centre = corners.mean(axis=1)
        radius = np.sqrt(np.max(np.sum((corners - centre[:, None]) ** 2, axis=2), axis=1))
        lists = cKDTree(centre).query_ball_point(queries[rows], dist[rows] + radius.max())
        at = np.repeat(np.arange(len(rows)), [len(x) for x in lists])
        tri = np.concatenate([np.asarray(x, dtype=np.int64) for x in lists])       # rows is not empty
        q = queries[rows[at]]
        near = ((np.linalg.norm(q - centre[tri], axis=1) - radius[tri] <= dist[rows[at]])
                & (edge[tri] >= need[at]))
        at, tri, q = at[near], tri[near], q[near]
        if not len(at):
            return
        b = closest_barycentric(q, corners[tri, 0], corners[tri, 1], corners[tri, 2])
        d = np.linalg.norm(np.einsum("nk,nkj->nj", b, corners[tri]) - q, axis=1)
        order = np.lexsort((d, at))                                  # per row, the closest first
        first = order[np.r_[True, at[order][1:] != at[order][:-1]]]
        better = d[first] < dist[rows[at[first]]]
        first = first[better]
        r = rows[at[first]]
        face[r], bary[r], dist[r] = subset[tri[first]], b[first], d[first]
        foot[r] = np.einsum("nk,nkj->nj", b[first], corners[tri[first]])

    def _rings(self, queries, k: int, within=None):
        """:meth:`_on_rings` in one piece per solver thread (rows are independent: the same answer)."""
        n = workers()
        if n < 2 or len(queries) < PIECE * n:
            return self._on_rings(queries, k, within)
        pieces = map_pieces(lambda rows: self._on_rings(queries[rows], k, None if within is None else within[rows]),
                            np.array_split(np.arange(len(queries)), n))
        return tuple(np.concatenate(part) for part in zip(*pieces))

    def _on_rings(self, queries, k: int, within=None):
        """Closest points on the triangles around each query's ``k`` nearest vertices: ``(face, bary,
        foot, distance, nearest vertex, distance of the k-th nearest vertex)``.  Each triangle is tried
        once per query (the rings of neighbouring vertices share most of theirs).  ``within (Q,)``: a
        distance each query's answer is known to be at most (m): triangles that :meth:`_beyond` proves
        farther are not tried (the answer is the same wherever one at most that far exists; a row with
        none gets distance inf)."""
        gap, near = self.tree.query(queries, k=k)
        near, gap = near.reshape(len(queries), -1), gap.reshape(len(queries), -1)
        tris = np.sort(self.ring[near].reshape(len(queries), -1), axis=1)   # (Q, k R), -1 padding first
        fresh = tris >= 0
        fresh[:, 1:] &= tris[:, 1:] != tris[:, :-1]
        row, col = np.nonzero(fresh)                                       # grouped by row, in order
        tri = tris[row, col]
        if within is not None:
            keep = ~self._beyond(queries[row], tri, within[row])
            row, tri = row[keep], tri[keep]
        vw, d2 = self._on_triangles(queries[row], tri)
        lowest = np.full(len(queries), np.inf)
        seen = np.flatnonzero(np.bincount(row, minlength=len(queries)))    # rows with a triangle
        if len(seen):
            lowest[seen] = np.minimum.reduceat(d2, np.searchsorted(row, seen))
        pick = np.flatnonzero(d2 <= lowest[row])
        pick = pick[np.diff(row[pick], prepend=-1) != 0]                    # the first closest of each row
        face = np.zeros(len(queries), np.int64)
        v, w = np.zeros(len(queries)), np.zeros(len(queries))
        dist = np.full(len(queries), np.inf)
        at = row[pick]
        face[at], v[at], w[at], dist[at] = tri[pick], vw[0][pick], vw[1][pick], np.sqrt(d2[pick])
        bary = np.stack([1.0 - v - w, v, w], axis=1)
        foot = self.corner[face] + v[:, None] * self.ab[face] + w[:, None] * self.ac[face]
        return face, bary, foot, dist, near[:, 0], gap[:, -1]

    def _beyond(self, points, tri, within):
        """True where triangle ``tri (M,)`` is provably farther than ``within (M,)`` from ``points (M, 3)``:
        the distance to its plane or to its bounding sphere (centroid, farthest corner) exceeds it by
        more than rounding (``BOUND_SLACK``), so no triangle at most ``within`` away is ever dropped."""
        bounds = self._bounds[tri] if len(tri) >= len(self.faces) else self._bounds_of(tri)   # (M, 8)
        plane = np.abs(_dot(points, bounds[:, :3]) - bounds[:, 3])
        off = points - bounds[:, 4:7]
        sphere = np.sqrt(_dot(off, off)) - bounds[:, 7]
        return np.maximum(plane, sphere) > within + BOUND_SLACK

    @functools.cached_property
    def _bounds(self):
        """:meth:`_bounds_of` every triangle (worth it when a search tries more pairs than there are)."""
        return self._bounds_of(slice(None))

    def _bounds_of(self, tri):
        """``(M, 8)`` of triangles ``tri``: unit normal n, n.a (its plane n.x = n.a), bounding sphere
        centre (the centroid) and radius (its farthest corner)."""
        corner, ab, ac, normal = self.corner[tri], self.ab[tri], self.ac[tri], self.face_normals[tri]
        centre = corner + (ab + ac) / 3.0
        corners = np.stack([corner, corner + ab, corner + ac], axis=1)
        radius = np.sqrt(np.max(np.sum((corners - centre[:, None]) ** 2, axis=2), axis=1))
        return np.column_stack([normal, _dot(normal, corner), centre, radius])

    def _on_triangles(self, points, tri):
        """``((v, w), squared distance)`` of the closest point ``a + v ab + w ac`` on triangles ``tri (M,)``
        to ``points (M, 3)``, from the triangles' edge vectors and Gram entries (:func:`_regions`)."""
        ap = points - self.corner[tri]
        ab, ac = self.ab[tri], self.ac[tri]
        v, w = _regions(_dot(ab, ap), _dot(ac, ap), *self.gram[tri].T)
        off = v[:, None] * ab + w[:, None] * ac - ap
        return (v, w), _dot(off, off)


def one_ring(faces, num_vertices: int) -> np.ndarray:
    """``(V, R)`` the triangles around each vertex, padded with -1 (R = largest valence)."""
    corner = np.asarray(faces, dtype=np.int64).ravel()
    if len(corner) == 0:
        raise ArticulaInputError("model: the mesh has no faces; tracking needs its surface")
    order = np.argsort(corner, kind="stable")
    counts = np.bincount(corner, minlength=num_vertices)
    starts = np.cumsum(counts) - counts
    table = np.full((num_vertices, max(int(counts.max()), 1)), -1, dtype=np.int64)
    v = corner[order]
    table[v, np.arange(len(order)) - starts[v]] = order // 3
    return table


def closest_barycentric(p, a, b, c):
    """Barycentric coordinates ``(..., 3)`` of the closest point to ``p`` on triangles ``(a, b, c)``
    (all ``(..., 3)``, broadcast), by :func:`_regions`."""
    ab, ac, ap = b - a, c - a, p - a
    v, w = _regions(_dot(ab, ap), _dot(ac, ap), _dot(ab, ab), _dot(ab, ac), _dot(ac, ac))
    return np.stack([1.0 - v - w, v, w], axis=-1)


def _regions(d1, d2, d00, d01, d11):
    """``(v, w)`` of the closest point ``a + v ab + w ac`` of a triangle to a point p, from ``d1 = ab.ap``,
    ``d2 = ac.ap`` and the Gram entries ``ab.ab, ab.ac, ac.ac`` (arrays, broadcast): the region tests of the
    point-triangle distance (Ericson, Real-Time Collision Detection §5.1.5), vectorised, with the dot
    products at b and c written through the Gram entries (``ab.bp = d1 - ab.ab`` ...).  Degenerate
    triangles give a corner or an edge."""
    d3, d4, d5, d6 = d1 - d00, d2 - d01, d1 - d01, d2 - d11
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    den = va + vb + vc
    inside = np.where(np.abs(den) > 1e-300, 1.0 / np.where(den == 0, 1.0, den), 0.0)
    v, w = vb * inside, vc * inside
    zero, one = np.zeros_like(v), np.ones_like(v)
    bc = _fraction(d4 - d3, (d4 - d3) + (d5 - d6))
    cases = (                                 # later cases take precedence, as in the sequential tests
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), 1.0 - bc, bc),          # edge bc
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), zero, _fraction(d2, d2 - d6)),      # edge ac
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), _fraction(d1, d1 - d3), zero),      # edge ab
        ((d6 >= 0) & (d5 <= d6), zero, one),                                     # corner c
        ((d3 >= 0) & (d4 <= d3), one, zero),                                     # corner b
        ((d1 <= 0) & (d2 <= 0), zero, zero),                                     # corner a
    )
    for mask, cv, cw in cases:
        v, w = np.where(mask, cv, v), np.where(mask, cw, w)
    return v, w


def _dot(x, y):
    return np.einsum("...i,...i->...", x, y)


def _fraction(num, den):
    """``num / den`` clipped to [0, 1] (0 where ``den`` is 0): the parameter along an edge."""
    return np.clip(num / np.where(den == 0, 1.0, den), 0.0, 1.0)
