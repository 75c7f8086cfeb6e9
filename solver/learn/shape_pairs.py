"""Left/right pairs of parts by their shape: a part and its mirror image match after a reflection and a
rigid motion, whatever pose either is in.

For creatures with neither a mirror-symmetric triangulation nor a symmetric scan (an animal captured in
motion), the vertex mirror map of :mod:`solver.learn.mirror_map` is missing and symmetry planes through
whole scans find no pairs.  Each part is rigid over the scans, so its rest vertices are a shape that the
pose does not change; the left foreleg's shape reflected is the right foreleg's.  :func:`shape_votes`
compares every two parts of alike size: part a reflected (x → −x), aligned to part b by ICP from the four
proper alignments of their principal axes, scored by the symmetric RMS nearest-point distance over the
parts' size (RMS distance to their centroid).  Pairs that are each other's best match within SHAPE_TOL
vote; left is the part whose joint lies on the positive side of the pairs' common left-right direction
(the summed joint differences, largest component positive, as in :mod:`solver.learn.symmetry`).
Positions in metres (any unit: all tests are relative).
"""
from itertools import product

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.procrustes import fit_rigid

SIZE_RATIO = 0.6            # candidates: vertex counts within this ratio ...
EXTENT_TOL = 0.2            # ... and principal extents within this fraction
SHAPE_TOL = 0.12            # a pair: reflected shapes within this RMS distance over the parts' size
POINTS = 300                # at most this many points of each part take part in the ICP
ICP_ITERATIONS = 15


def _sample(pts, count=POINTS):
    if len(pts) <= count:
        return pts
    return pts[np.linspace(0, len(pts) - 1, count).round().astype(np.int64)]


def _principal(pts):
    """``(centred points, axes (3,3) columns, extents (3,) descending)``."""
    c = pts - pts.mean(axis=0)
    val, vec = np.linalg.eigh(c.T @ c / len(c))
    return c, vec[:, ::-1], np.sqrt(np.maximum(val[::-1], 0.0))


def mirror_match(a, b):
    """Symmetric RMS nearest-point distance between ``a (Na,3)`` reflected (x → −x) and ``b (Nb,3)``
    after the best rigid alignment (ICP from the principal-axes starts), over the shapes' size."""
    a = _sample(a) * [-1.0, 1.0, 1.0]
    b = _sample(b)
    ca, Va, _ = _principal(a)
    cb, Vb, _ = _principal(b)
    size = np.sqrt(0.5 * (np.mean(np.sum(ca ** 2, 1)) + np.mean(np.sum(cb ** 2, 1))))
    tb, best = cKDTree(cb), np.inf
    for signs in product((1.0, -1.0), repeat=2):
        S = np.diag([signs[0], signs[1], signs[0] * signs[1]])
        x = ca @ (Vb @ S @ Va.T).T
        for _ in range(ICP_ITERATIONS):
            R, t = fit_rigid(x, cb[tb.query(x)[1]])
            x = x @ R.T + t
        d_ab = tb.query(x)[0]
        d_ba = cKDTree(x).query(cb)[0]
        best = min(best, float(np.sqrt(0.5 * (np.mean(d_ab ** 2) + np.mean(d_ba ** 2)))) / max(size, 1e-300))
    return best


def shape_votes(rest, labels, order, head_of_part, weight=1):
    """Votes ``{(left part, right part): weight}`` of the parts of ``labels (V,)`` on ``rest (V,3)`` that
    are each other's mirror image (module docstring); ``order (k,)`` parts breadth first (the root first),
    ``head_of_part (k,3)`` each part's joint with its parent."""
    k = len(order)
    pts = [rest[labels == p] for p in range(k)]
    ext = [_principal(x)[2] if len(x) >= 4 else None for x in pts]
    score, count = np.full((k, k), np.inf), [len(x) for x in pts]
    for a in range(k):
        for b in range(a + 1, k):
            if ext[a] is None or ext[b] is None or min(count[a], count[b]) < SIZE_RATIO * max(count[a], count[b]):
                continue
            if np.any(np.abs(ext[a] - ext[b]) > EXTENT_TOL * np.maximum(ext[a], ext[b])):
                continue
            score[a, b] = score[b, a] = mirror_match(pts[a], pts[b])
    pairs = sorted((score[a, b], a, b) for a in range(k) for b in range(a + 1, k)
                   if score[a, b] <= SHAPE_TOL and np.argmin(score[a]) == b and np.argmin(score[b]) == a)
    if not pairs:
        return {}
    n = _side_normal(head_of_part, [(a, b) for _, a, b in pairs])
    return {((a, b) if (head_of_part[a] - head_of_part[b]) @ n >= 0 else (b, a)): weight for _, a, b in pairs}


def _side_normal(head_of_part, pairs):
    """The left-right direction ``(3,)`` of the pairs' joints: the sum of their differences turned to
    agree with the best pair's, its largest component positive (as :mod:`solver.learn.symmetry`)."""
    a, b = pairs[0]
    n = np.zeros(3)
    ref = head_of_part[a] - head_of_part[b]
    for a, b in pairs:
        d = head_of_part[a] - head_of_part[b]
        n += d if d @ ref >= 0 else -d
    n = n / max(np.linalg.norm(n), 1e-300)
    return n if n[int(np.argmax(np.abs(n)))] >= 0 else -n
