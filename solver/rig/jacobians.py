"""Analytic Jacobians of hybrid-skinned vertices, for the Levenberg–Marquardt solvers (:mod:`solver.fit`).

Pose parameters of one frame, in this order (``P = 4 + 3 B``; see :func:`pose_layout`):
* ``t`` (3): root translation, world metres, additive (t ← t + dt);
* ``s`` (1): uniform subject scale, additive (s ← s + ds);
* ``δ_b`` (3 per bone, b = 0 … B−1): rotation increment as a rotation vector (angle = norm, radians)
  in the bone's *local* axes, applied on the right: ``q_b ← q_b · exp(δ_b)`` (bone 0 = root rotation).
:func:`apply_pose_increment` applies exactly this update, so a solver can iterate
``J Δ = −r; poses = apply_pose_increment(poses, Δ)``.

Joint-centre parameters: the rest heads ``(B, 3)`` (world metres), moved additively with rest frames,
tails and rest vertices held fixed (the dissertation's Chapter 4 adapts only joint locations;
dissertation (model-adaptive mocap) §2).  Frame parameters (:func:`frame_jacobian`): a world axis-angle ω_b
per rest frame, ``F_b ← exp(ω_b) F_b``, with every bone's world rotation held fixed
(:func:`apply_frame_increment`), as the dissertation's Chapter 3 optimises the joint orientations.

Shapes: Jacobians are dense per-vertex blocks ``(N, V, 3, P)`` (resp. ``(N, V, 3, 3B)``); memory is
N·V·3·P·8 bytes (13,380 vertices × 19 bones ≈ 20 MB per frame).  Each vertex has non-zero columns only
for t, s, its anchor's chain and its anchor's children; :func:`to_sparse` turns one frame into a
``scipy.sparse.csr_matrix`` of shape (3V, P) (rows x0, y0, z0, x1, …).  Solvers use the factored form
of one anchor group instead (:func:`group_jacobian`): ``J = R T`` with per-vertex columns
``R (N, V_a, 3, r)`` (r = 6 plus the columns of the blended children) and a per-frame combination
``T (N, r, P)``; :func:`factored_gram` gives its normal equations without forming J.

Derivation (world axes; Rm_b = s·Rot_b is the chain of part b, p_b its posed joint):
* chain bone b of the anchor: ∂x'/∂δ_b = −[x' − p_b]× Rot_b F_b;  ∂x'/∂h_b = Rm_parent(b) − Rm_b
  (I − Rm_0 for the root);
* child c of the anchor: through the twist (DLB: chain rule through the normalising dual-quaternion map
  and the swing/twist split) and the swing (LBS: ∂R_sw = R_sw [ω]×);  see the helper docstrings.
"""

import numpy as np

from ..errors import ArticulaInputError
from .model import Poses
from ..geometry.rotations import (quat_canonical, quat_conj, quat_mul, quat_normalize, quat_to_matrix, rotvec_to_quat,
                        swing_twist_y)
from .skinning import (_apply_affine_components, _apply_dq_components, _groups_for, blend_group, bone_terms,
                       check_pose_shapes, twist_signs)

_TWIST_EPS = 1e-12


def pose_layout(num_bones: int) -> dict:
    """Column slices of the pose parameters: ``translation``, ``scale``, and ``rotation(b)``."""
    return {"translation": slice(0, 3), "scale": slice(3, 4),
            "rotation": lambda b: slice(4 + 3 * b, 7 + 3 * b), "size": 4 + 3 * num_bones}


def apply_pose_increment(poses: Poses, delta) -> Poses:
    """New poses after the increment ``delta`` (N, P) in the layout of :func:`pose_layout`."""
    delta = np.asarray(delta, dtype=np.float64)
    N, B = poses.rotations.shape[:2]
    if delta.shape != (N, 4 + 3 * B):
        raise ArticulaInputError(f"delta: expected shape ({N}, {4 + 3 * B}), got {delta.shape}")
    d_rot = delta[:, 4:].reshape(N, B, 3)
    rotations = quat_normalize(quat_mul(poses.rotations, rotvec_to_quat(d_rot)))
    return Poses(rotations, poses.translations + delta[:, :3], poses.scales + delta[:, 3])


def _skew(v):
    """Cross-product matrices ``(..., 3, 3)`` of vectors ``(..., 3)``: skew(a) @ b = a × b."""
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([z, -w, y, w, z, -x, -y, x, z], axis=-1).reshape(v.shape + (3,))


def _left(q):
    """(…, 4, 4) matrix of p ↦ q·p."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([w, -x, -y, -z, x, w, -z, y, y, z, w, -x, z, -y, x, w], -1).reshape(q.shape + (4,))


def _right(q):
    """(…, 4, 4) matrix of p ↦ p·q."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([w, -x, -y, -z, x, w, z, -y, y, -z, w, x, z, y, -x, w], -1).reshape(q.shape + (4,))


def _split_derivatives(q):
    """Derivatives of the swing/twist split w.r.t. q (canonical, (N, B, 4)).

    Returns ``d_twist (N, B, 2, 4)`` of the twist components (w_t, y_t) = (w, y)/√(w²+y²) and
    ``d_swing (N, B, 4, 4)`` of q_swing = q · q_twist*.  Where the twist is undefined (w²+y² ≈ 0) the
    twist is held at identity and its derivative is 0."""
    w, y = q[..., 0], q[..., 2]
    n2 = w * w + y * y
    ok = n2 > _TWIST_EPS
    inv3 = np.where(ok, 1.0 / np.where(ok, n2, 1.0) ** 1.5, 0.0)
    z = np.zeros_like(w)
    d_twist = np.stack([y * y, z, -w * y, z, -w * y, z, w * w, z], axis=-1).reshape(q.shape[:-1] + (2, 4))
    d_twist = d_twist * inv3[..., None, None]
    _, q_tw = swing_twist_y(q)
    d_tw4 = np.zeros(q.shape[:-1] + (4, 4))
    d_tw4[..., 0, :], d_tw4[..., 2, :] = d_twist[..., 0, :], d_twist[..., 1, :]
    conj = np.diag([1.0, -1.0, -1.0, -1.0])
    d_swing = _right(quat_conj(q_tw)) + _left(q) @ conj @ d_tw4
    return d_twist, d_swing


def _pose_bone_terms(skeleton, poses):
    """Per (frame, bone) Jacobian pieces on top of :func:`skinning.bone_terms`:
    ``T (N, B, 8, 3)`` = ∂(world twist dual quaternion)/∂δ, ``G (N, B, 3, 3)`` = world swing angular
    velocity per δ (∂R_sw = R_sw [G δ]×), ``K (N, B, 3, 3)`` = Rot_b F_b (chain), ``p (N, B, 3)`` the
    posed joints, ``R_sw (N, B, 3, 3)`` world swing rotations."""
    terms = bone_terms(skeleton, poses)
    F, h = skeleton.frames, skeleton.heads
    q = quat_canonical(quat_normalize(poses.rotations))
    E = 0.5 * _left(q)[..., 1:]                                      # ∂q/∂δ for q·exp(δ), (N, B, 4, 3)
    d_twist, d_swing = _split_derivatives(q)
    Y = F[:, :, 1]
    dQ = np.zeros((len(F), 8, 2))                                    # ∂Q/∂(w_t, y_t), (B, 8, 2)
    dQ[:, 0, 0] = 1.0
    dQ[:, 1:4, 1] = Y
    dQ[:, 5:8, 1] = np.cross(h, Y)
    T = dQ @ d_twist @ E
    q_sw, _ = swing_twist_y(q)
    omega = 2.0 * _left(quat_conj(q_sw))[..., 1:, :] @ d_swing @ E   # body angular velocity of the swing
    G = F @ omega
    s = poses.scales[:, None, None, None]
    Rm, tm = terms["Rm"], terms["tm"]
    K = (Rm / s) @ F
    p = np.einsum("nbij,bj->nbi", Rm, h) + tm
    R_sw = F @ quat_to_matrix(q_sw) @ np.swapaxes(F, -1, -2)
    return dict(terms, T=T, G=G, K=K, p=p, R_sw=R_sw)


def _dq_apply_jacobian(b, x):
    """∂/∂b of the normalising dual-quaternion map f(b, x) (dualquat.dq_apply).

    b (…, 8) un-normalised, x (…, 3) broadcastable.  Returns (…, 3, 8).  With (a_w, a) = b0, (d_w, d) = bε,
    n2 = |b0|², g = a × (a × x + a_w x) + a_w d − d_w a + a × d and f = x + 2 g / n2:
    ∂f/∂b = (2/n2) ∂g/∂b − (4/n2²) g [b0ᵀ 0], with the columns of ∂g/∂b
    ∂g/∂a_w = a × x + d, ∂g/∂a = a xᵀ + (a·x) I − 2 x aᵀ − a_w [x]× − d_w I − [d]×, ∂g/∂d_w = −a,
    ∂g/∂d = a_w I + [a]×.
    Written entry by entry on the component arrays (…) into a component-major array, returned as a
    (…, 3, 8) view: numpy's inner loops over short trailing 3 × 8 dimensions (a broadcasting form) would
    be the cost."""
    b = np.asarray(b, dtype=np.float64)
    x = np.broadcast_to(np.asarray(x, dtype=np.float64), b.shape[:-1] + (3,))
    aw, a0, a1, a2, dw, d0, d1, d2 = (b[..., i] for i in range(8))
    x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
    s = 2.0 / (aw * aw + a0 * a0 + a1 * a1 + a2 * a2)
    t = s * s                                                         # 4 / n2²
    c0, c1, c2 = a1 * x2 - a2 * x1, a2 * x0 - a0 * x2, a0 * x1 - a1 * x0       # a × x
    u0, u1, u2 = c0 + aw * x0, c1 + aw * x1, c2 + aw * x2
    e0, e1, e2 = u0 + d0, u1 + d1, u2 + d2                             # a × (u + d) = a × u + a × d
    g = (a1 * e2 - a2 * e1 + aw * d0 - dw * a0, a2 * e0 - a0 * e2 + aw * d1 - dw * a1,
         a0 * e1 - a1 * e0 + aw * d2 - dw * a2)
    ax = a0 * x0 + a1 * x1 + a2 * x2
    a, xs, ds = (a0, a1, a2), (x0, x1, x2), (d0, d1, d2)
    J = np.empty((3, 8) + b.shape[:-1])            # component-major: contiguous rows
    for i in range(3):
        ti = t * g[i]
        J[i, 0] = s * ((c0, c1, c2)[i] + ds[i]) - ti * aw
        J[i, 4] = -s * a[i]
        for k in range(3):
            dgik = a[i] * xs[k] - 2.0 * xs[i] * a[k]
            if i == k:
                dgik = dgik + ax - dw
                J[i, 5 + k] = s * aw
            else:                                         # [v]×_ik = ε_ijk… written out: sign · v_m
                m = 3 - i - k
                sign = 1.0 if (i, k) in ((0, 2), (1, 0), (2, 1)) else -1.0
                dgik = dgik - sign * (aw * xs[m] + ds[m])
                J[i, 5 + k] = s * (sign * a[m])
            J[i, 1 + k] = s * dgik - ti * a[k]
    return np.moveaxis(J, (0, 1), (-2, -1))


def _chain_of(skeleton, a):
    """Bones of the chain of part a: a, parent(a), …, 0."""
    out = [a]
    while skeleton.parents[out[-1]] >= 0:
        out.append(int(skeleton.parents[out[-1]]))
    return out


def _skew_times(w, H):
    """``[w]× H`` for vectors w ``(..., 3)`` and matrices H ``(..., 3, 3)`` (broadcasting), without
    forming the cross-product matrix."""
    w0, w1, w2 = w[..., 0, None], w[..., 1, None], w[..., 2, None]
    H0, H1, H2 = H[..., 0, :], H[..., 1, :], H[..., 2, :]
    return np.stack([w1 * H2 - w2 * H1, w2 * H0 - w0 * H2, w0 * H1 - w1 * H0], axis=-2)


def _per_frame_matmul(X, Y):
    """``X (N, V, 3, k) @ Y (N, k, m)`` for every vertex, as one BLAS product per frame."""
    N, V, r, k = X.shape
    return (X.reshape(N, V * r, k) @ Y).reshape(N, V, r, Y.shape[-1])


def _group_posed(bt, groups, group):
    """Rest points ``x (V_a, 3)`` of one anchor group and, for all frames, the blended twist
    ``bq (N, V_a, 8)``, the twisted points ``v_t (N, V_a, 3)``, the linear part ``L3 (N, V_a, 3, 3)`` of
    the swing∘chain map (None for a group without children) and the posed points ``(N, V_a, 3)``, by the
    component formulas of :func:`skinning.hybrid_skin`."""
    a, kids, start, stop, wt, ws = group
    N, Va = len(bt["Rm"]), stop - start
    x = groups.rest[:, start:stop]
    tw, sw = blend_group(bt, 0, N, a, kids, wt, ws)                  # (8, N, V_a), (12, N, V_a)
    vt = _apply_dq_components(tw, x) if len(kids) else np.broadcast_to(x[:, None], (3, N, Va))
    xp = _apply_affine_components(sw, vt)
    L3 = np.moveaxis(sw, 0, -1).reshape(N, Va, 3, 4)[..., :3] if len(kids) else None
    return x.T, np.moveaxis(tw, 0, -1), np.moveaxis(vt, 0, -1), L3, np.moveaxis(xp, 0, -1)


def jacobian_terms(model, poses, heads=False, frame_basis=None):
    """Per (frame, bone) quantities shared by all anchor groups of one Jacobian evaluation: those of
    :func:`_pose_bone_terms` plus ``sk`` (the skeleton), ``s (N, 1, 1)`` scales, ``t (N, 3)``
    translations; with ``heads``: ``chain_block (N, B, 3, 3)`` = ∂x'/∂h_b through the chain and
    ``T_head (N, B, 8, 3)`` = ∂(world twist dual quaternion)/∂h_b; with ``frame_basis (B, 3, m_f)``:
    the frame terms of :func:`_frame_bone_terms` for rotations ω_b = frame_basis[b] @ θ (θ (m_f,)
    radians): ``T_f (N, B, 8, m_f)``, ``G_f (N, B, 3, m_f)``."""
    sk = model.skeleton
    bt = _pose_bone_terms(sk, poses)
    bt.update(sk=sk, s=poses.scales[:, None, None], t=poses.translations)
    if heads:
        Rm = bt["Rm"]
        chain_block = np.empty_like(Rm)
        chain_block[:, 0] = np.eye(3) - Rm[:, 0]
        chain_block[:, 1:] = Rm[:, np.maximum(sk.parents[1:], 0)] - Rm[:, 1:]
        T_head = np.zeros(Rm.shape[:2] + (8, 3))                     # ∂(dual vector h × u)/∂h = −[u]×
        T_head[..., 5:8, :] = -_skew(bt["twist_dq"][..., 1:4])
        bt.update(chain_block=chain_block, T_head=T_head)
    if frame_basis is not None:
        T, G = _frame_bone_terms(sk, poses)
        bt.update(T_f=T @ frame_basis, G_f=G @ frame_basis)
    return bt


def piece_width(key, terms):
    """Columns of one Jacobian piece (see :func:`group_jacobian`)."""
    if key == "s":
        return 1
    if key[0] == "frame":
        return terms["T_f"].shape[-1]
    return 3


def group_jacobian(bt, groups, group, cols, width, extra=0):
    """Jacobian of one anchor group in factored form ``J = R T`` (one product per frame).

    bt: :func:`jacobian_terms`; group: an entry of ``groups.groups`` (:class:`AnchorGroups`);
    cols: the first column (< width) of every wanted piece: ``"t"`` (3: root translation), ``"s"``
    (1: scale), ``("rot", b)`` (3: δ_b), ``("head", b)`` (3: heads[b]; needs ``heads``),
    ``("frame", b)`` (m_f: frame rotation; needs ``frame_basis``).
    Returns the posed points ``(N, V_a, 3)`` (metres), the per-vertex columns ``R (N, V_a, 3, r + extra)``
    = ``[I | −[x' − c]× | x' − c (only with "s") | blended-child pieces]`` (c = the posed joint of the
    anchor; the ``extra`` last columns are left to the caller) and ``T (N, r, width)``, their
    combination into the wanted pieces (zero columns elsewhere).  Every vertex moves rigidly with its
    anchor's chain except through its blended children, so the chain pieces need no per-vertex columns:
    ∂x'/∂δ_b = [p_b − x']× K_b = [p_b − c]× K_b − [x' − c]× K_b, ∂x'/∂h_b = chain_block_b, ∂x'/∂t = I."""
    a, kids, start, stop, wt, ws = group
    x, bq, vt, L3, xp = _group_posed(bt, groups, group)
    kid_keys = [[(kind, c) for kind in ("rot", "frame", "head") if (kind, c) in cols] for c in kids]
    n0 = 7 if "s" in cols else 6
    r = n0 + sum(piece_width(k, bt) for keys in kid_keys for k in keys)
    N, Va = xp.shape[:2]
    R = np.empty((N, Va, 3, r + extra))
    T = np.zeros((N, r, width))
    d = xp - bt["p"][:, a, None]
    R[..., :3] = np.eye(3)
    _minus_skew_into(d, R[..., 3:6])
    if n0 == 7:
        R[..., 6] = d
    _chain_combination(bt, a, cols, T)
    if not any(kid_keys):
        return xp, R, T
    L3Jdq = L3 @ _dq_apply_jacobian(bq, x)                           # (N, V_a, 3, 8)
    swt = signed_twist_weights(bt, kids, wt)
    j = n0
    for k, (c, keys) in enumerate(zip(kids, kid_keys)):
        if keys:
            blk = _kid_block(bt, a, c, swt[..., k], ws[:, k], L3Jdq, vt, keys)
            R[..., j:j + blk.shape[-1]] = blk
            for key in keys:
                m = piece_width(key, bt)
                T[:, j + np.arange(m), cols[key] + np.arange(m)] = 1.0
                j += m
    return xp, R, T


def _minus_skew_into(d, out):
    """``out (..., 3, 3) = −[d]×`` for vectors ``d (..., 3)``."""
    out[..., 0, 0] = out[..., 1, 1] = out[..., 2, 2] = 0.0
    out[..., 0, 1], out[..., 0, 2] = d[..., 2], -d[..., 1]
    out[..., 1, 0], out[..., 1, 2] = -d[..., 2], d[..., 0]
    out[..., 2, 0], out[..., 2, 1] = d[..., 1], -d[..., 0]


def _chain_combination(bt, a, cols, T):
    """Rows 0-6 of ``T (N, r, width)`` for the pieces of group a's chain (:func:`group_jacobian`):
    ``[p_b − c]× K_b`` and ``K_b`` for δ_b, chain_block_b for h_b, I for t, and for s
    ``(x' − h_0 − t)/s = (c − h_0 − t)/s + (x' − c)/s``."""
    c = bt["p"][:, a]
    if "t" in cols:
        T[:, :3, cols["t"]:cols["t"] + 3] = np.eye(3)
    if "s" in cols:
        T[:, :3, cols["s"]] = (c - bt["sk"].heads[0] - bt["t"]) / bt["s"][:, 0]
        T[:, 6, cols["s"]] = 1.0 / bt["s"][:, 0, 0]
    for b in _chain_of(bt["sk"], a):
        if ("rot", b) in cols:
            j = cols[("rot", b)]
            T[:, :3, j:j + 3] = _skew_times(bt["p"][:, b] - c, bt["K"][:, b])
            T[:, 3:6, j:j + 3] = bt["K"][:, b]
        if ("head", b) in cols:
            T[:, :3, cols[("head", b)]:cols[("head", b)] + 3] = bt["chain_block"][:, b]


def signed_twist_weights(bt, kids, wt):
    """Twist weights ``(N, V_a, K)`` times the hemisphere signs of skinning.twist_signs (the signs are
    piecewise constant, so they pass through the derivative unchanged)."""
    N = bt["Rm"].shape[0]
    signs = twist_signs(bt, 0, N, kids, wt)
    return np.broadcast_to(wt[None], (N,) + wt.shape) if signs is None else signs * wt[None]


def _kid_block(bt, a, c, wt_k, ws_k, L3Jdq, vt, keys):
    """Columns ``(N, V_a, 3, m)`` of a blended child c for the pieces ``keys`` (in the order rot, frame,
    head).  ``wt_k (N, V_a)``: the child's signed twist weight (:func:`signed_twist_weights`),
    ``ws_k (V_a,)`` its swing weight.  A piece that moves the world twist dual quaternion by
    ``T (N, 8, m)`` and the world swing by ``∂R_sw = R_sw [G ·]×`` (G (N, 3, m)) has twist part
    ``w_t L3 (∂f/∂b) T`` and swing part ``w_s Rm_a R_sw [G·]× (v_t − h_c)`` =
    ``−w_s [RR (v_t − h_c)]× (RR G / s)`` (RR = Rm_a R_sw = s·rotation); a head moves the swing map's
    translation: ``w_s Rm_a (I − R_sw)``.  All three as one product per frame: the per-vertex rows
    ``[w_t L3 ∂f/∂b | −w_s [RR (v_t − h_c)]× | w_s I]`` ``(N, V_a, 3, 8 + 3 + 3)`` times the per-frame
    ``[T; RR G / s; Rm_a (I − R_sw)]`` (zero where a piece has no such part): one pass over the vertices'
    columns instead of one per term."""
    names = {"rot": ("T", "G"), "frame": ("T_f", "G_f"), "head": ("T_head", None)}
    T = np.concatenate([bt[names[k[0]][0]][:, c] for k in keys], axis=-1)            # (N, 8, m)
    Gs = [bt[names[k[0]][1]][:, c] for k in keys if k[0] != "head"]
    head = keys[-1][0] == "head"
    N, m = T.shape[0], T.shape[-1]
    Va = len(ws_k)
    width = 8 + 3 * bool(Gs) + 3 * head
    left = np.empty((N, Va, 3, width))
    np.multiply(wt_k[..., None, None], L3Jdq, out=left[..., :8])
    right = np.zeros((N, width, m))
    right[:, :8] = T
    Rm_a, R_sw = bt["Rm"][:, a], bt["R_sw"][:, c]
    RR = Rm_a @ R_sw
    j = 8
    if Gs:
        G = np.concatenate(Gs, axis=-1)
        lever = (vt - bt["sk"].heads[c]) @ np.swapaxes(RR, 1, 2)         # RR (v_t − h_c), (N, V_a, 3)
        _minus_skew_into(ws_k[None, :, None] * lever, left[..., j:j + 3])
        right[:, j:j + 3, :G.shape[-1]] = (RR @ G) / bt["s"]
        j += 3
    if head:
        left[..., j:j + 3] = 0.0
        for i in range(3):
            left[..., i, j + i] = ws_k
        right[:, j:j + 3, -3:] = Rm_a @ (np.eye(3) - R_sw)
    return _per_frame_matmul(left, right)


def dense_jacobian(model, poses, cols, width, groups=None, heads=False, frame_basis=None):
    """Posed vertices ``(N, V, 3)`` and the Jacobian ``(N, V, 3, width)`` with the pieces at the columns
    ``cols`` (:func:`group_jacobian`), zero elsewhere.  ``groups``: optional :class:`AnchorGroups`."""
    groups = _groups_for(model, groups)
    posed, J = sorted_jacobian(model, poses, cols, width, groups, heads, frame_basis)
    inv = groups.inverse
    return posed[:, inv], J[:, inv]


def sorted_jacobian(model, poses, cols, width, groups, heads=False, frame_basis=None, dtype=np.float64):
    """:func:`dense_jacobian` in the anchor-sorted vertex order of ``groups`` (row ``groups.inverse[v]``
    is vertex v's) and of ``dtype``: what a caller that looks rows up keeps, without the reordered copy."""
    check_pose_shapes(model, poses)
    bt = jacobian_terms(model, poses, heads, frame_basis)
    N, V = len(poses), model.num_vertices
    posed = np.empty((N, V, 3))
    J = np.empty((N, V, 3, width), dtype=dtype)
    for group in groups.groups:
        xp, R, T = group_jacobian(bt, groups, group, cols, width)
        posed[:, group[2]:group[3]], J[:, group[2]:group[3]] = xp, _per_frame_matmul(R, T)
    return posed, J


def factored_gram(R, T):
    """Gram matrices of ``[R T | ρ]`` for a group Jacobian in factored form (:func:`group_jacobian` with
    ``extra=1``, the caller's residual ρ in the last column of R): ``T̃ᵀ (Rᵀ R) T̃`` with
    ``T̃ = [[T, 0], [0, 1]]``.  R (N, V_a, 3, r+1), T (N, r, C); returns (N, C+1, C+1): the normal matrix
    ``JᵀJ``, the gradient ``Jᵀρ`` (last column) and ``ρᵀρ`` (corner) of every frame."""
    return expand_gram(gram(R), T)


def gram(X):
    """``Xᵀ X`` per frame of ``X (N, R, 3, C)`` as (N, C, C) (one BLAS product per frame)."""
    X = X.reshape(len(X), -1, X.shape[-1])
    return np.matmul(np.swapaxes(X, 1, 2), X)


def expand_gram(G, T):
    """``T̃ᵀ G T̃`` with ``T̃ = [[T, 0], [0, 1]]``: Gram matrices ``G (N, r+1, r+1)`` of ``[R | ρ]`` to those
    of ``[R T | ρ]``; T (N, r, C)."""
    N, r, C = T.shape
    Te = np.zeros((N, r + 1, C + 1))
    Te[:, :r, :C], Te[:, r, C] = T, 1.0
    return np.swapaxes(Te, 1, 2) @ G @ Te


def pose_jacobian(model, poses, groups=None):
    """Posed vertices ``(N, V, 3)`` and their Jacobian ``(N, V, 3, P)`` w.r.t. the pose parameters
    (module docstring for the layout and conventions).  ``groups``: optional :class:`AnchorGroups`."""
    B = model.skeleton.num_bones
    cols = {"t": 0, "s": 3, **{("rot", b): 4 + 3 * b for b in range(B)}}
    return dense_jacobian(model, poses, cols, 4 + 3 * B, groups)


def joint_jacobian(model, poses, groups=None):
    """Posed vertices ``(N, V, 3)`` and their Jacobian ``(N, V, 3, 3B)`` w.r.t. the rest joint centres
    ``heads`` (columns 3b … 3b+2 = x, y, z of heads[b]; frames, tails, rest vertices fixed).
    ``groups``: optional :class:`AnchorGroups`."""
    B = model.skeleton.num_bones
    return dense_jacobian(model, poses, {("head", b): 3 * b for b in range(B)}, 3 * B, groups, heads=True)


def apply_frame_increment(skeleton, poses, omega):
    """Rotate rest frames by world axis-angle vectors ``omega (B, 3)``: ``F_b ← exp(ω_b) F_b`` (tails
    follow, heads stay), and re-express every local pose quaternion ``q ← g q g*`` with
    ``g = quat(F'ᵀ F)`` so each bone's *world* rotation is unchanged; only the swing/twist split moves.
    Returns ``(skeleton, poses)``."""
    from .model import Skeleton
    from ..geometry.rotations import matrix_to_quat, rotvec_to_matrix
    omega = np.asarray(omega, dtype=np.float64)
    B = skeleton.num_bones
    if omega.shape != (B, 3):
        raise ArticulaInputError(f"omega: expected shape ({B}, 3), got {omega.shape}")
    F = skeleton.frames
    F_new = rotvec_to_matrix(omega) @ F
    g = matrix_to_quat(np.swapaxes(F_new, -1, -2) @ F)
    q = quat_normalize(quat_mul(quat_mul(g, poses.rotations), quat_conj(g)))
    length = np.linalg.norm(skeleton.tails - skeleton.heads, axis=1)
    sk = Skeleton(list(skeleton.names), skeleton.parents.copy(), skeleton.heads.copy(),
                  skeleton.heads + length[:, None] * F_new[:, :, 1], F_new)
    return sk, Poses(q, poses.translations.copy(), poses.scales.copy())


def _frame_bone_terms(skeleton, poses):
    """Per (frame, bone) derivatives of the world twist w.r.t. a frame rotation ω (world axis-angle)
    with the world rotation fixed: ``T (N, B, 8, 3)`` and ``G (N, B, 3, 3)`` (see :func:`_kid_block`).

    With world quaternion (w, u) of the bone's rotation and twist axis Y: η = Y·u, n = √(w² + η²),
    twist (w_t, y_t) = (w, η)/n, world twist dual quaternion ((w_t, y_t Y), (0, y_t h × Y)).
    ∂η/∂ω = (Y × u)ᵀ, ∂Y/∂ω = −[Y]×; the swing R R_tw⁻¹ changes by −R_sw [Θ·]×, Θ = 2 vec(∂Q_t ⊗ Q_t*)."""
    F, h = skeleton.frames, skeleton.heads
    q = quat_canonical(quat_normalize(poses.rotations))
    w = q[..., 0]
    u = np.einsum("bij,nbj->nbi", F, q[..., 1:])                     # world vector part
    Y = np.broadcast_to(F[:, :, 1], u.shape)
    eta = np.sum(Y * u, axis=-1)
    n2 = w * w + eta * eta
    ok = n2 > _TWIST_EPS
    n3 = np.where(ok, np.where(ok, n2, 1.0) ** 1.5, np.inf)
    y_t = np.where(ok, eta / np.sqrt(np.where(ok, n2, 1.0)), 0.0)
    d_eta = np.cross(Y, u)                                           # (N, B, 3)
    dw_t = (-w * eta / n3)[..., None] * d_eta
    dvec = Y[..., :, None] * ((w * w / n3)[..., None] * d_eta)[..., None, :] - y_t[..., None, None] * _skew(Y)
    dQt = np.concatenate([dw_t[..., None, :], dvec], axis=-2)        # (N, B, 4, 3)
    T = np.zeros(u.shape[:-1] + (8, 3))
    T[..., :4, :] = dQt
    T[..., 5:8, :] = _skew(np.broadcast_to(h, u.shape)) @ dvec
    Qt = np.concatenate([np.where(ok, w / np.sqrt(np.where(ok, n2, 1.0)), 1.0)[..., None],
                         y_t[..., None] * Y], axis=-1)
    theta = 2.0 * _right(quat_conj(Qt))[..., 1:, :] @ dQt
    return T, -theta


def frame_jacobian(model, poses, groups=None):
    """Posed vertices ``(N, V, 3)`` and their Jacobian ``(N, V, 3, 3B)`` w.r.t. world axis-angle
    rotations ω_b of the rest frames, with the update of :func:`apply_frame_increment` (each bone's world
    rotation kept, so only the swing/twist split of blended children moves; heads fixed).  Columns
    3b … 3b+2 = ω_b.  For rotations about the frame's own X and Z axes use ``J_b @ F_b[:, 0]`` and
    ``J_b @ F_b[:, 2]`` (or :func:`dense_jacobian` with ``frame_basis``).  ``groups``: optional
    :class:`AnchorGroups`."""
    B = model.skeleton.num_bones
    basis = np.broadcast_to(np.eye(3), (B, 3, 3))
    return dense_jacobian(model, poses, {("frame", b): 3 * b for b in range(B)}, 3 * B, groups,
                          frame_basis=basis)


def to_sparse(J_frame):
    """One frame's dense Jacobian ``(V, 3, P)`` as a ``scipy.sparse.csr_matrix`` of shape (3V, P)."""
    import scipy.sparse as sp
    V, _, P = J_frame.shape
    return sp.csr_matrix(J_frame.reshape(3 * V, P))
