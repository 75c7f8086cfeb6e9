"""Posed positions of single vertices under candidate anchors and weights: the hybrid skin
(docs/skinning.md) evaluated per candidate anchor, affine in the swing weights.

Layout: scan-major, component in the middle, candidates last, ``(M, comp, n)``, so the per-scan maps are
applied to all candidates of one anchor by one batched matrix product per scan and every elementwise
operation runs over contiguous rows of n candidates.  Metres throughout."""
import numpy as np

from ...rig.skinning import bone_terms, running_flips
from .candidates import by_label, children_table


def _dq_apply_soa(b, x, out):
    """Blended twist dual quaternions given as components ``b`` (list of 8 ``(M,n)`` arrays; b[4], the
    real part of the dual half, is 0 for rotations about a point and not read) applied to rest points
    ``x (3,n)``, written to ``out (M,3,n)``.  The normalising formula of :func:`dualquat.dq_apply` with
    q = (w, u), dual vector d and s = 2/|q|²: ``x + s (u × (u × x + w x + d) + w d)``."""
    w, u0, u1, u2, _, d0, d1, d2 = b
    s = 2.0 / (w * w + u0 * u0 + u1 * u1 + u2 * u2)
    x0, x1, x2 = x
    y0 = u1 * x2 - u2 * x1 + w * x0 + d0
    y1 = u2 * x0 - u0 * x2 + w * x1 + d1
    y2 = u0 * x1 - u1 * x0 + w * x2 + d2
    out[:, 0] = x0 + s * (u1 * y2 - u2 * y1 + w * d0)
    out[:, 1] = x1 + s * (u2 * y0 - u0 * y2 + w * d1)
    out[:, 2] = x2 + s * (u0 * y1 - u1 * y0 + w * d2)


_DQ_PARTS = (0, 1, 2, 3, 5, 6, 7)          # non-zero components of twist dual quaternions


def _twist_blend(q, wt):
    """``identity (1 − Σ w) + Σ_c s_c w_c q_c`` as 8 components ``(M,n)`` (component 4 is None: zero) for
    the twist dual quaternions of an anchor's children ``q (M,8,k)`` and weights ``wt (k,n)``, with the
    running hemisphere rule of :mod:`solver.rig.skinning` for k ≥ 2: s_c = −1 where q_c's real part points
    away from the sum so far, starting from the neutral's share (which can be −1e-8 when float32 weights
    sum to just over 1: the rule then flips the first child, as ``hybrid_skin`` does).

    The signs come from :func:`solver.rig.skinning.running_flips` (scans as its frames, candidates as its
    vertices), the blend is one matrix product ``(7M, k) @ (k, n)`` with the unsigned weights plus a
    correction where a sign is −1 (rare): for k = 2 about 15 instead of 60 passes over ``(M,n)`` arrays.
    Same values as the per-child blend up to rounding."""
    M, _, k = q.shape
    n = wt.shape[1]
    rest = 1 - wt.sum(axis=0)
    flips = running_flips(q[:, :4].transpose(0, 2, 1), wt.T) if k >= 2 else [None] * k   # (M,n) masks
    parts = np.ascontiguousarray(q[:, _DQ_PARTS].transpose(1, 0, 2)).reshape(len(_DQ_PARTS) * M, k)
    blend = (parts @ wt).reshape(len(_DQ_PARTS), M, n)
    blend[0] += rest
    for j, flip in enumerate(flips):
        if flip is not None:
            corr = np.where(flip, -2.0 * wt[j], 0.0)
            for c in range(len(_DQ_PARTS)):
                blend[c] += q[:, _DQ_PARTS[c], j, None] * corr
    out = [None] * 8
    for c, i in enumerate(_DQ_PARTS):
        out[i] = blend[c]
    return out


def _twist_one(x, w, centre, axis, cos_half, sin_half, out):
    """The twist blend for an anchor with one child, in closed form: ``identity (1 − w) + w q`` with q the
    rotation by φ about the child's fixed twist axis through its head is, normalised, the rotation about
    that axis by θ with ``(cos θ/2, sin θ/2) ∝ (1 − w + w cos φ/2, w sin φ/2)`` (the same dual quaternion
    as :func:`_twist_blend` + :func:`_dq_apply_soa`, in about half the operations).

    x ``(3,n)`` rest points, w ``(n,)`` twist weights, centre, axis ``(3,)`` (unit), cos_half, sin_half
    ``(M,)`` per scan.  Writes the twisted points to ``out (M,3,n)``."""
    xc = x - centre[:, None]
    p = xc - axis[:, None] * (axis @ xc)                              # component normal to the axis
    q = np.stack([axis[1] * p[2] - axis[2] * p[1], axis[2] * p[0] - axis[0] * p[2],
                  axis[0] * p[1] - axis[1] * p[0]])                     # axis × p (as np.cross)
    on_axis = x - p
    r0 = (cos_half - 1)[:, None] * w                                 # (M,n); in place from here on
    r0 += 1
    s = sin_half[:, None] * w
    cos = r0 * r0                                                    # r0², then cos θ
    s2 = s * s
    inv = cos + s2
    np.divide(1, inv, out=inv)
    cos -= s2
    cos *= inv
    sin = r0
    sin *= 2                                                         # 2 r0 s / (r0² + s²)
    sin *= s
    sin *= inv
    tmp = s2
    for i in range(3):
        o = out[:, i]
        np.multiply(cos, p[i], out=o)
        o += on_axis[i]
        np.multiply(sin, q[i], out=tmp)
        o += tmp


class CandidateSkin:
    """Posed positions of single vertices under candidate anchors/weights, from the per-(scan, bone) terms
    of :func:`solver.rig.skinning.bone_terms` computed once (skeleton and poses are fixed during BCD).

    For a vertex x with anchor a, twist weights w_t and swing weights w_s on C(a):
    ``v_t = DLB(identity + Σ_c w_t,c (dq_c − identity)) x`` and
    ``p = M_a(v_t) + Σ_c w_s,c (S_c(v_t) − M_a(v_t))`` with ``S_c = M_parent(c) ∘ Swing_c`` — the hybrid skin
    of docs/skinning.md, affine in w_s; ``S_c − M_a`` is itself one affine map.  Candidates are evaluated
    per anchor (:meth:`columns`): M_a and the k maps S_c − M_a are stacked into one ``(3(k+1), 4)`` matrix
    per scan and applied to all the group's twisted points by one batched product.  (Checked against
    ``hybrid_skin`` in the tests.)"""

    def __init__(self, skeleton, poses):
        t = bone_terms(skeleton, poses)
        parents = np.asarray(skeleton.parents)
        self.kids = [np.flatnonzero(parents == b) for b in range(len(parents))]
        self.K = children_table(parents).shape[1]
        self.M, B = t["twist_dq"].shape[:2]
        self._q = t["twist_dq"].transpose(0, 2, 1)                                # (M,8,B)
        self._heads = np.asarray(skeleton.heads, dtype=np.float64)
        self._axes = np.asarray(skeleton.frames, dtype=np.float64)[:, :, 1]        # twist axes (B,3)
        self._chain = t["chain"].reshape(self.M, B, 3, 4)
        self._swing = t["swing_chain"].reshape(self.M, B, 3, 4)
        self._terms = {}

    def _anchor_terms(self, a):
        """Cached ``(q (M,8,k), maps (M,3(k+1),4))`` of anchor a: its children's twist dual quaternions
        and the rows of M_a followed by those of S_c − M_a for each child c."""
        if a not in self._terms:
            kids = self.kids[a]
            chain = self._chain[:, a]
            maps = np.concatenate([chain[:, None], self._swing[:, kids] - chain[:, None]], axis=1)
            self._terms[a] = (np.ascontiguousarray(self._q[:, :, kids]),
                              np.ascontiguousarray(maps.reshape(self.M, -1, 4)))
        return self._terms[a]

    def columns(self, a, x, wt):
        """Candidates with anchor a: rest points ``x (3,n)``, twist weights ``wt (k,n)`` on ``kids[a]``.
        Returns ``C (M,3(k+1),n)``: rows 0:3 the posed position with swing weights 0 (base), rows
        3(j+1):3(j+2) the effect of swing weight 1 on ``kids[a][j]`` (column G_j).  Metres."""
        q, maps = self._anchor_terms(a)
        n = x.shape[1]
        x = np.asarray(x, np.float64)
        wt = np.asarray(wt, np.float64)
        if q.shape[2] == 0:
            return np.matmul(maps, np.concatenate([x, np.ones((1, n))]))
        vt = np.empty((self.M, 4, n))
        vt[:, 3] = 1
        if q.shape[2] == 1:
            c = self.kids[a][0]
            axis = self._axes[c]
            _twist_one(x, wt[0], self._heads[c], axis, q[:, 0, 0], q[:, 1:4, 0] @ axis, vt)
        else:
            _dq_apply_soa(_twist_blend(q, wt), x, vt)
        return np.matmul(maps, vt)

    def base_and_columns(self, x, anchor, twist, kids):
        """x (n,3), anchor (n,), twist (n,B) float, kids (n,K) children of the anchor (-1 padded).
        Returns ``base (M,n,3)`` (swing weights 0) and ``G (M,n,3,K)`` (column j: effect of swing weight 1
        on kids[:, j]; 0 for padding), float64 (the reference layout of the tests)."""
        n, K = kids.shape
        base = np.empty((self.M, n, 3))
        G = np.zeros((self.M, n, 3, K))
        for a, rows in by_label(np.asarray(anchor)):
            ka = self.kids[a]
            C = self.columns(a, x[rows].T, twist[rows[:, None], ka[None, :]].T)
            C = C.reshape(self.M, len(ka) + 1, 3, len(rows))
            base[:, rows] = C[:, 0].transpose(0, 2, 1)
            G[:, rows, :, :len(ka)] = C[:, 1:].transpose(0, 3, 2, 1)
        return base, G


def dot(a, b):
    """``Σ_m,i a b`` ``(n,)`` of two ``(M,3,n)`` arrays."""
    return np.einsum("min,min->n", a, b)


def normal_equations(C, r):
    """``H = Σ_m,i G_k G_l`` ``(n,k,k)`` and ``b = Σ_m,i G_k r`` ``(n,k)`` (float64) for the swing columns
    of ``C (M,3(k+1),n)`` (:meth:`CandidateSkin.columns`) and residuals ``r (M,3,n)``."""
    k, n = C.shape[1] // 3 - 1, C.shape[2]
    G = [C[:, 3 * (j + 1):3 * (j + 2)] for j in range(k)]
    H = np.empty((n, k, k))
    b = np.empty((n, k))
    for i in range(k):
        b[:, i] = dot(G[i], r)
        for j in range(i, k):
            H[:, i, j] = H[:, j, i] = dot(G[i], G[j])
    return H, b

