"""Skinning: plain linear blend skinning, Blender-style dual-quaternion skinning, and the exact hybrid
swing/twist skin (dissertation (model-adaptive mocap) §1.2-1.6; docs/skinning.md).

Shapes: rest vertices ``(V, 3)`` metres; bone maps ``Rm (N, B, 3, 3)``, ``tm (N, B, 3)`` (part b maps
x -> Rm x + tm, e.g. from :func:`kinematics.forward_kinematics`); posed vertices ``(N, V, 3)``.

Hybrid skin of rest vertex v with anchor a and blend set C(a) = children of a, for one frame:
1. twist: DLB of "rotate by the world twist of c about heads[c]" (c ∈ C(a), weights twist_weights[v, c])
   with the identity taking the remainder;  2. swing: linear blend of "rotate by the world swing of c
   about heads[c]" with the identity taking the remainder;  3. the anchor chain M_a.
Implementation: every vertex touches only the ≤ K children of its anchor, so vertices are grouped by
anchor; per (frame, bone) we precompute the world twist dual quaternion and the composite affine map
``M_parent(c) ∘ Swing_c``; per group two small matrix products blend them (weights compact ``(V_a, K_a)``).
Hemisphere rule of the twist DLB (the dissertation leaves the pivot open, dissertation (model-adaptive mocap)
§1.4): the neutral comes first, then the children of the anchor in ascending bone order, and each child's
twist dual quaternion is flipped when its real part points away from the weighted sum accumulated so far. This
is exactly what Blender's "Preserve Volume" does with the rig's vertex groups (NEUTRAL written first, then
``TW-*`` in bone order), so the native rig reproduces the solver everywhere, including large opposing twists
at forks. Twist quaternions have w >= 0 after canonicalisation, so flips only happen when two twisting
children of one vertex turn by more than 180° together; the rule is antipodally invariant.
"""
import numpy as np

from .. import parallel
from ..errors import ArticulaInputError
from ..geometry.dualquat import IDENTITY as DQ_IDENTITY
from ..geometry.dualquat import dq_apply, dq_from_rigid, align_hemisphere
from .kinematics import chain_from_world, to_world
from ..geometry.rotations import quat_canonical, quat_normalize, quat_to_matrix, swing_twist_y

FRAME_CHUNK = 32
PARALLEL_VERTEX_FRAMES = 50_000    # hybrid_skin splits its frames over the solver's threads from this size


# ----------------------------------------------------------------------------- plain LBS and DQS

def _flat_maps(Rm, tm):
    """(N, B, 3, 3), (N, B, 3) -> (N, B, 12) rows [R00 R01 R02 t0 R10 ... t2]."""
    return np.concatenate([Rm, tm[..., None]], axis=-1).reshape(Rm.shape[:2] + (12,))


def _weights_times(weights, T):
    """weights (V, B) dense or scipy sparse, T (B, C) -> (V, C) dense."""
    out = weights @ T
    return np.asarray(out)


def _check_maps(vertices, weights, Rm, tm):
    """Shape checks shared by :func:`lbs` and :func:`dqs` (ArticulaInputError naming the argument)."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ArticulaInputError(f"vertices: expected shape (V, 3), got {v.shape}")
    if np.ndim(Rm) != 4 or np.shape(Rm)[2:] != (3, 3):
        raise ArticulaInputError(f"Rm: expected shape (N, B, 3, 3), got {np.shape(Rm)}")
    N, B = np.shape(Rm)[:2]
    if np.shape(tm) != (N, B, 3):
        raise ArticulaInputError(f"tm: expected shape ({N}, {B}, 3), got {np.shape(tm)}")
    if tuple(weights.shape) != (len(v), B):
        raise ArticulaInputError(f"weights: expected shape ({len(v)}, {B}), got {tuple(weights.shape)}")
    return v


def lbs(vertices, weights, Rm, tm):
    """Linear blend skinning with a neutral remainder: ``Σ_b w_b (Rm_b v + tm_b) + (1 − Σ_b w_b) v``.

    vertices (V, 3); weights (V, B) dense array or scipy.sparse matrix (rows summing to 1 give
    classical LBS); Rm (N, B, 3, 3), tm (N, B, 3).  Returns (N, V, 3)."""
    if not hasattr(weights, "tocsr"):
        weights = np.asarray(weights, dtype=np.float64)
    v = _check_maps(vertices, weights, Rm, tm)
    N, B = Rm.shape[:2]
    ident = np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1).reshape(12)
    D = _flat_maps(Rm, tm) - ident                      # (N, B, 12), neutral subtracted
    out = np.empty((N, len(v), 3))
    for n0 in range(0, N, FRAME_CHUNK):
        Dc = D[n0:n0 + FRAME_CHUNK]
        n = len(Dc)
        blend = _weights_times(weights, Dc.transpose(1, 0, 2).reshape(B, n * 12))   # (V, n*12)
        blend = blend.reshape(len(v), n, 3, 4).transpose(1, 0, 2, 3)                # (n, V, 3, 4)
        out[n0:n0 + n] = v + np.einsum("nvij,vj->nvi", blend[..., :3], v) + blend[..., 3]
    return out


def _compact(weights):
    """Dense/sparse (V, B) weights -> indices (V, K) and weights (V, K) of the non-zeros (padded with
    index 0 and weight 0)."""
    if hasattr(weights, "tocsr"):
        w = weights.tocsr(copy=True)
        w.eliminate_zeros()
        w.sort_indices()
        counts = np.diff(w.indptr)
        K = max(int(counts.max()) if len(counts) else 0, 1)
        V = w.shape[0]
        idx = np.zeros((V, K), dtype=np.int64)
        val = np.zeros((V, K))
        rows = np.repeat(np.arange(V), counts)
        slot = np.arange(len(w.indices)) - np.repeat(w.indptr[:-1], counts)
        idx[rows, slot] = w.indices
        val[rows, slot] = w.data
        return idx, val
    w = np.asarray(weights, dtype=np.float64)
    K = max(int((w != 0).sum(axis=1).max()) if len(w) else 0, 1)
    idx = np.argsort(w == 0, axis=1, kind="stable")[:, :K]
    return idx, np.take_along_axis(w, idx, axis=1)


def _align_running(dq, w):
    """Blender's hemisphere rule: walk a vertex's bones in order (K axis) and flip each dual quaternion
    whose real part has a negative dot product with the weighted sum so far.  dq (N, V, K, 8),
    w (V, K).  Returns the aligned copy."""
    out = dq.copy()
    total = np.zeros(dq.shape[:2] + (4,))
    for k in range(dq.shape[2]):
        flip = np.einsum("nvi,nvi->nv", out[:, :, k, :4], total) < 0
        out[:, :, k] = np.where(flip[..., None], -out[:, :, k], out[:, :, k])
        total += w[None, :, k, None] * out[:, :, k, :4]
    return out


def dqs(vertices, weights, Rm, tm, align="running"):
    """Dual-quaternion skinning as Blender's Armature modifier with "Preserve Volume" does it.

    Rows of weights (dense (V, B) or scipy.sparse) are normalised by their sum (rows summing to 0 stay
    at rest); each bone map x -> Rm x + tm must be a rotation times a uniform scale s_b: the scale is
    blended linearly and applied first, the rigid parts are blended as dual quaternions, normalised and
    applied.  Hemisphere alignment: ``align="running"`` (Blender's rule: bones in ascending index order,
    each flipped when it points away from the running weighted sum) or ``"max"`` (every bone aligned to
    the vertex's largest-weight bone).  Returns (N, V, 3)."""
    if not hasattr(weights, "tocsr"):
        weights = np.asarray(weights, dtype=np.float64)
    v = _check_maps(vertices, weights, Rm, tm)
    idx, w = _compact(weights)
    total = w.sum(axis=1)
    moving = total > 0
    w = np.where(moving[:, None], w / np.where(moving, total, 1.0)[:, None], 0.0)
    s = np.cbrt(np.linalg.det(Rm))                                   # (N, B)
    DQ = dq_from_rigid(Rm / s[..., None, None], tm)                  # (N, B, 8)
    dq = DQ[:, idx]                                                   # (N, V, K, 8)
    if align == "running":
        dq = _align_running(dq, w)
    elif align == "max":
        pivot = quat_canonical(np.take_along_axis(dq[..., :4], np.argmax(w, axis=1)[None, :, None, None],
                                                  axis=2)[:, :, 0])
        dq = align_hemisphere(dq, pivot)
    else:
        raise ArticulaInputError(f"align: expected 'running' or 'max', got {align!r}")
    blended = np.einsum("vk,nvki->nvi", w, dq)
    blended = np.where(moving[None, :, None], blended, DQ_IDENTITY)
    scale = np.where(moving, np.einsum("vk,nvk->nv", w, s[:, idx]), 1.0)
    posed = dq_apply(blended, scale[..., None] * v)
    return np.where(moving[None, :, None], posed, v)


# ----------------------------------------------------------------------------- hybrid skin

def check_pose_shapes(model, poses):
    """Raise ArticulaInputError unless ``poses`` fits ``model`` (shapes only; values are checked by
    ``Poses.validate``, the model by ``Model.validate``, once, when loaded or built)."""
    B = model.skeleton.num_bones
    r = np.shape(poses.rotations)
    if len(r) != 3 or r[1:] != (B, 4):
        raise ArticulaInputError(f"pose_rotations: expected shape (N, {B}, 4) for this model, got {r}")
    N = r[0]
    if np.shape(poses.translations) != (N, 3):
        raise ArticulaInputError(f"pose_translations: expected shape ({N}, 3), got {np.shape(poses.translations)}")
    if np.shape(poses.scales) != (N,):
        raise ArticulaInputError(f"pose_scales: expected shape ({N},), got {np.shape(poses.scales)}")
    V = len(model.rest_vertices)
    for key in ("anchor", "twist_weights", "swing_weights"):
        if len(getattr(model, key)) != V:
            raise ArticulaInputError(f"{key}: {len(getattr(model, key))} rows for {V} rest vertices")


def bone_terms(skeleton, poses):
    """Per (frame, bone) quantities of the hybrid skin, computed once and shared by all vertices.

    Returns a dict of arrays: ``twist_dq (N, B, 8)`` world twist of bone b about heads[b] as a dual
    quaternion (w >= 0); ``swing_chain (N, B, 12)`` the affine map ``M_parent(b) ∘ Swing_b`` (row-major
    3x4; unused for the root); ``chain (N, B, 12)`` the part maps ``M_b``; ``Rm (N, B, 3, 3)``,
    ``tm (N, B, 3)`` the part maps as matrices."""
    F, h = skeleton.frames, skeleton.heads
    q = quat_canonical(quat_normalize(poses.rotations))
    q_sw, q_tw = swing_twist_y(q)
    u = q_tw[..., 2:3] * F[:, :, 1]                                    # (N, B, 3) world twist vector part
    twist_dq = np.concatenate([q_tw[..., :1], u, np.zeros(u.shape[:-1] + (1,)), np.cross(h, u)], axis=-1)
    R_sw = to_world(F, quat_to_matrix(q_sw))                           # (N, B, 3, 3)
    R = to_world(F, quat_to_matrix(q))
    Rm, tm = chain_from_world(skeleton, R, poses.translations, poses.scales)
    par = np.maximum(skeleton.parents, 0)
    Rp, tp = Rm[:, par], tm[:, par]
    sw_lin = Rp @ R_sw
    sw_t = np.einsum("nbij,nbj->nbi", Rp, h - np.einsum("nbij,bj->nbi", R_sw, h)) + tp
    return dict(twist_dq=twist_dq, swing_chain=_flat_maps(sw_lin, sw_t), chain=_flat_maps(Rm, tm), Rm=Rm, tm=tm)


class AnchorGroups:
    """Vertices grouped by anchor part, with compact blend-set weights: a snapshot of the model's
    anchors and weights (build a new one after changing them).  Pass it to :func:`hybrid_skin`,
    :func:`affine_form` or the Jacobians to skip the set-up when the skin is fixed (e.g. tracking).

    ``order (V,)`` sorts vertices by anchor, ``inverse (V,)`` undoes it; ``rest (3, V)`` rest vertices
    in sorted order; ``groups`` lists ``(a, children (K,), start, stop, twist (V_a, K), swing (V_a, K))``
    for every anchor part with vertices (rows start:stop of the sorted order, float64 weights)."""

    def __init__(self, model):
        anchor = model.anchor
        B = model.skeleton.num_bones
        self.num_vertices = len(anchor)
        self.order = np.argsort(anchor, kind="stable")
        self.inverse = np.empty_like(self.order)
        self.inverse[self.order] = np.arange(len(anchor))
        self.rest = np.ascontiguousarray(model.rest_vertices[self.order].T)
        bounds = np.searchsorted(anchor[self.order], np.arange(B + 1))
        twist, swing = model.twist_weights[self.order], model.swing_weights[self.order]
        self.groups = []
        for a in range(B):
            start, stop = int(bounds[a]), int(bounds[a + 1])
            if stop > start:
                kids = np.asarray(model.skeleton.children(a), dtype=np.int64)
                self.groups.append((a, kids, start, stop, twist[start:stop, kids].astype(np.float64),
                                    swing[start:stop, kids].astype(np.float64)))


def _groups_for(model, groups):
    if groups is None:
        return AnchorGroups(model)
    if groups.num_vertices != model.num_vertices:
        raise ArticulaInputError(f"groups: built for {groups.num_vertices} vertices, model has {model.num_vertices}")
    return groups


def running_flips(Q, wt):
    """The running-sum hemisphere rule (module docstring): per child k, the ``(n, V)`` bool mask of the
    entries where its twist dual quaternion is flipped, or None where it never is.  Q ``(n, K, 4)``: the
    children's twist dual quaternions' real parts per frame; wt ``(V, K)`` twist weights.

    Child k's test ``⟨q_k, e (1 − Σ w) + Σ_{i<k} s_i w_i q_i⟩ < 0`` is evaluated as
    ``q_k,w (1 − Σ w) + Σ_{i<k} D_ki s_i w_i`` with the per-frame dot products ``D (n, K, K)`` of the real
    parts, so each child costs k passes over ``(n, V)`` arrays instead of a 4-vector sum per vertex and
    frame.  Shared by :func:`twist_signs` (frames × vertices) and the weight search's candidate blends
    (scans × candidates)."""
    D = np.einsum("nki,nli->nkl", Q, Q)                                  # (n, K, K)
    rest = 1.0 - wt.sum(axis=1)                                          # (V,)
    flips, signed = [], []                                               # signed: s_k w_k, (n, V) or (V,)
    for k in range(Q.shape[1]):
        dot = Q[:, k, 0, None] * rest
        for i in range(k):
            dot += D[:, k, i, None] * signed[i]
        flip = (dot < 0) & (wt[None, :, k] > 0)
        if flip.any():
            flips.append(flip)
            signed.append(np.where(flip, -wt[:, k], wt[:, k]))
        else:
            flips.append(None)
            signed.append(wt[:, k])
    return flips


def _group_flips(terms, n0, n1, kids, wt):
    """:func:`running_flips` of one anchor group's children over frames n0:n1 (all None for < 2)."""
    if len(kids) < 2:
        return [None] * len(kids)
    return running_flips(terms["twist_dq"][n0:n1][:, kids, :4], wt)


def twist_signs(terms, n0, n1, kids, wt):
    """Signs ``(n, V_a, K)`` (±1.0) of the children's twist dual quaternions under the running-sum
    hemisphere rule (:func:`running_flips`) for frames n0:n1, or None when nothing is flipped (the usual
    case).  kids (K,) ascending bone indices; wt (V_a, K) twist weights."""
    flips = _group_flips(terms, n0, n1, kids, wt)
    if all(f is None for f in flips):
        return None
    signs = np.ones((n1 - n0, len(wt), len(kids)))
    for k, flip in enumerate(flips):
        if flip is not None:
            signs[..., k] = np.where(flip, -1.0, 1.0)
    return signs


def blend_group(terms, n0, n1, a, kids, wt, ws):
    """Blended twist dual quaternions ``(8, n, V_a)`` (un-normalised) and swing∘chain affine maps
    ``(12, n, V_a)`` (row-major 3x4) of one anchor group over frames n0:n1, component-major so each
    component is a contiguous (n, V_a) array.  Twist: ``e + Σ_c w_t,c (Q_c − e)`` (e = identity);
    swing: ``M_a + Σ_c w_s,c (M_a ∘ Swing_c − M_a)``.  Where the hemisphere rule flips a child
    (:func:`running_flips`), ``e (1 − Σ w) + Σ s w Q`` differs from that by ``−2 w_c Q_c``, added at
    those (frame, vertex) entries only."""
    chain_a = terms["chain"][n0:n1, a].T[:, :, None]                   # (12, n, 1)
    n, Va = n1 - n0, len(wt)
    if len(kids) == 0:
        tw = np.broadcast_to(DQ_IDENTITY[:, None, None], (8, n, Va))
        return tw, np.broadcast_to(chain_a, (12, n, Va))
    Q = terms["twist_dq"][n0:n1][:, kids]                                            # (n, K, 8)
    dt = (Q - DQ_IDENTITY).transpose(2, 0, 1)                                        # (8, n, K)
    tw = (dt.reshape(8 * n, len(kids)) @ wt.T).reshape(8, n, Va) + DQ_IDENTITY[:, None, None]
    for k, flip in enumerate(_group_flips(terms, n0, n1, kids, wt)):
        if flip is not None:
            f, v = np.nonzero(flip)
            tw[:, f, v] -= 2.0 * wt[v, k] * Q[f, k].T
    ds = terms["swing_chain"][n0:n1][:, kids] - terms["chain"][n0:n1, a][:, None]   # (n, K, 12)
    sw = (ds.transpose(2, 0, 1).reshape(12 * n, len(kids)) @ ws.T).reshape(12, n, Va) + chain_a
    return tw, sw


def _apply_dq_components(tw, x):
    """Apply blended dual quaternions given as components ``(8, n, V)`` to points ``x`` (3, V) with the
    normalising formula of dualquat.dq_apply.  Returns (3, n, V)."""
    aw, ax, ay, az, dw, dx, dy, dz = tw
    inv = 2.0 / (aw * aw + ax * ax + ay * ay + az * az)
    px, py, pz = x[0], x[1], x[2]
    # c = a × x + a_w x
    cx = ay * pz - az * py + aw * px
    cy = az * px - ax * pz + aw * py
    cz = ax * py - ay * px + aw * pz
    # e = a × c + a_w d − d_w a + a × d  =  a × (c + d) + a_w d − d_w a
    sx, sy, sz = cx + dx, cy + dy, cz + dz
    ex = ay * sz - az * sy + aw * dx - dw * ax
    ey = az * sx - ax * sz + aw * dy - dw * ay
    ez = ax * sy - ay * sx + aw * dz - dw * az
    return np.stack([px + inv * ex, py + inv * ey, pz + inv * ez])


def _apply_affine_components(sw, x):
    """Apply affine maps given as components (12, n, V) (row-major 3x4) to points (3, n, V)."""
    return np.stack([sw[4 * i] * x[0] + sw[4 * i + 1] * x[1] + sw[4 * i + 2] * x[2] + sw[4 * i + 3]
                     for i in range(3)])


def hybrid_skin(model, poses, groups=None):
    """Posed vertices ``(N, V, 3)`` of the hybrid swing/twist skin (the steps of the module docstring).
    ``groups``: an optional :class:`AnchorGroups` of this model (built here when omitted)."""
    check_pose_shapes(model, poses)
    groups = _groups_for(model, groups)
    terms = bone_terms(model.skeleton, poses)
    N, V = len(poses), model.num_vertices
    out = np.empty((N, V, 3))
    step = FRAME_CHUNK
    if N * V >= PARALLEL_VERTEX_FRAMES:                # frame chunks on the solver's threads
        step = parallel.piece_size(N, FRAME_CHUNK)

    def frames(n0):
        n1 = min(N, n0 + step)
        chunk = np.empty((3, n1 - n0, V))
        for a, kids, start, stop, wt, ws in groups.groups:
            tw, sw = blend_group(terms, n0, n1, a, kids, wt, ws)
            x = groups.rest[:, start:stop]
            vt = _apply_dq_components(tw, x) if len(kids) else x[:, None]
            chunk[:, :, start:stop] = _apply_affine_components(sw, vt)
        out[n0:n1] = chunk[:, :, groups.inverse].transpose(1, 2, 0)

    parallel.map_pieces(frames, range(0, N, step))
    return out


def twist_flips(model, poses, groups=None):
    """``(N, V)`` bool: where the running-sum hemisphere rule flips one of a vertex's twists (module
    docstring).  Informational: Blender's rig applies the same rule, so results stay exact there."""
    check_pose_shapes(model, poses)
    groups = _groups_for(model, groups)
    terms = bone_terms(model.skeleton, poses)
    out = np.zeros((len(poses), model.num_vertices), dtype=bool)
    for a, kids, start, stop, wt, ws in groups.groups:
        signs = twist_signs(terms, 0, len(poses), kids, wt)
        if signs is not None:
            out[:, start:stop] = (signs < 0).any(axis=2)
    return out[:, groups.inverse]


def _dq_components_to_rigid(tw):
    """Rotation components ``R[i][j]`` (each (n, V)) and translation (3, n, V) of blended dual
    quaternions (8, n, V), normalised as in dualquat.dq_apply."""
    aw, ax, ay, az, dw, dx, dy, dz = tw
    s = 2.0 / (aw * aw + ax * ax + ay * ay + az * az)
    R = [[1 - s * (ay * ay + az * az), s * (ax * ay - aw * az), s * (ax * az + aw * ay)],
         [s * (ax * ay + aw * az), 1 - s * (ax * ax + az * az), s * (ay * az - aw * ax)],
         [s * (ax * az - aw * ay), s * (ay * az + aw * ax), 1 - s * (ax * ax + ay * ay)]]
    t = [s * (aw * dx - dw * ax + ay * dz - az * dy),
         s * (aw * dy - dw * ay + az * dx - ax * dz),
         s * (aw * dz - dw * az + ax * dy - ay * dx)]
    return R, t


def affine_form(model, poses, groups=None):
    """Per-vertex affine form of the hybrid skin (dissertation (model-adaptive mocap) §1.6):
    ``A (N, V, 3, 3)``, ``b (N, V, 3)`` with posed vertex = A @ rest vertex + b.  A = L · R_D and b = L t_D + l, where (R_D, t_D) is the vertex's
    normalised DLB twist and (L, l) its blended swing∘chain map; A is not orthogonal when swing
    weights are fractional."""
    check_pose_shapes(model, poses)
    groups = _groups_for(model, groups)
    terms = bone_terms(model.skeleton, poses)
    N, V = len(poses), model.num_vertices
    A = np.empty((3, 3, N, V))
    b = np.empty((3, N, V))
    for a, kids, start, stop, wt, ws in groups.groups:
        tw, sw = blend_group(terms, 0, N, a, kids, wt, ws)
        R, t = _dq_components_to_rigid(tw)
        for i in range(3):
            Li = sw[4 * i:4 * i + 4]
            for j in range(3):
                A[i, j, :, start:stop] = Li[0] * R[0][j] + Li[1] * R[1][j] + Li[2] * R[2][j]
            b[i, :, start:stop] = Li[0] * t[0] + Li[1] * t[1] + Li[2] * t[2] + Li[3]
    inv = groups.inverse
    return A[..., inv].transpose(2, 3, 0, 1), b[..., inv].transpose(1, 2, 0)
