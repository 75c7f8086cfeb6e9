"""Hybrid swing/twist skinning (dissertation (model-adaptive mocap) §8.1 S7, S9-S16), LBS and DQS against
literal references."""
import numpy as np
import pytest

from articula.solver.geometry import dualquat as dq
from articula.solver.rig import kinematics
from articula.solver.rig import skinning
from articula.sample_scenes import synthetic
from articula.solver.geometry import rotations as rot
from articula.solver.rig.model import Model, Poses, Skeleton, frames_from_bones

RNG = np.random.default_rng(5)


def literal_hybrid(model, poses):
    """Independent reference: the steps of skinning's module docstring for one vertex and frame at a time,
    with 4x4 homogeneous chain matrices and the generic DLB of dualquat."""
    sk = model.skeleton
    N, V = len(poses), model.num_vertices
    out = np.zeros((N, V, 3))
    for n in range(N):
        chain = []
        sw_world, tw_dq = [], []
        for b in range(sk.num_bones):
            F, h = sk.frames[b], sk.heads[b]
            q = poses.rotations[n, b]
            q_sw, q_tw = rot.swing_twist_y(q)
            sw_world.append(F @ rot.quat_to_matrix(q_sw) @ F.T)
            tw_dq.append(dq.dq_rotation_about(rot.matrix_to_quat(F @ rot.quat_to_matrix(q_tw) @ F.T), h))
            R = F @ rot.quat_to_matrix(q) @ F.T
            M = np.eye(4)
            if b == 0:
                M[:3, :3] = poses.scales[n] * R
                M[:3, 3] = h - M[:3, :3] @ h + poses.translations[n]
                chain.append(M)
            else:
                M[:3, :3] = R
                M[:3, 3] = h - R @ h
                chain.append(chain[sk.parents[b]] @ M)
        for v in range(V):
            a = model.anchor[v]
            kids = sk.children(a)
            x = model.rest_vertices[v]
            if kids:
                wt = model.twist_weights[v, kids].astype(float)
                blended = dq.dlb(wt, np.array([tw_dq[c] for c in kids]), pivot="running")
                x = dq.dq_apply(blended, x)
                ws = model.swing_weights[v, kids].astype(float)
                x = (1 - ws.sum()) * x + sum(w * (sw_world[c] @ (x - sk.heads[c]) + sk.heads[c])
                                             for w, c in zip(ws, kids))
            out[n, v] = chain[a][:3, :3] @ x + chain[a][:3, 3]
    return out


@pytest.fixture(scope="module")
def human():
    return synthetic.random_model(120, seed=1), synthetic.random_poses(3, 19, seed=2, max_angle=2.5)


def test_hybrid_matches_literal_reference(human):
    model, poses = human
    np.testing.assert_allclose(skinning.hybrid_skin(model, poses), literal_hybrid(model, poses), atol=1e-12)


def test_opposing_fork_twists_use_the_running_hemisphere_rule():
    """Two children of one anchor (the collarbones, pointing in opposite directions) twisted by 170°
    in their local axes turn in opposite world senses: their twist quaternions point into opposite
    hemispheres of the running sum, the rule flips one, and hybrid_skin still equals the literal
    reference (neutral first, children in bone order) and its affine form."""
    sk = synthetic.human_skeleton()
    model = synthetic.random_model(200, seed=4)
    fork, kids = min(((a, pair) for a in range(sk.num_bones) for pair in
                      [(c, d) for c in sk.children(a) for d in sk.children(a) if c < d]),
                     key=lambda ap: sk.frames[ap[1][0], :, 1] @ sk.frames[ap[1][1], :, 1])
    assert sk.frames[kids[0], :, 1] @ sk.frames[kids[1], :, 1] < -0.9
    r = np.zeros((2, sk.num_bones, 3))
    r[:, kids, 1] = np.radians(170.0)
    r[1, kids[1], 1] = np.radians(-120.0)          # frame 1: same world sense, nothing flips there
    poses = Poses(rot.rotvec_to_quat(r), np.zeros((2, 3)), np.ones(2))
    wt = np.zeros_like(model.twist_weights)
    sel = np.flatnonzero(model.anchor == fork)
    wt[sel, kids[0]] = 0.4
    wt[sel, kids[1]] = 0.4
    kids = list(kids)
    model = Model(model.rest_vertices, model.faces, model.skeleton, model.anchor, wt, model.swing_weights)
    flips = skinning.twist_flips(model, poses)
    assert flips[0, sel].all() and not flips[1].any() and not np.delete(flips[0], sel).any()
    got = skinning.hybrid_skin(model, poses)
    np.testing.assert_allclose(got, literal_hybrid(model, poses), atol=1e-12)
    A, b = skinning.affine_form(model, poses)
    np.testing.assert_allclose(np.einsum("nvij,vj->nvi", A, model.rest_vertices) + b, got, atol=1e-12)
    # aligning to the identity instead gives a visibly different (wrong-for-Blender) blend
    ident = dq.dlb(np.array([0.4, 0.4]), np.stack([dq.dq_rotation_about(rot.rotvec_to_quat(
        sk.frames[c] @ r[0, c]), sk.heads[c]) for c in kids]), pivot="identity")
    run = dq.dlb(np.array([0.4, 0.4]), np.stack([dq.dq_rotation_about(rot.rotvec_to_quat(
        sk.frames[c] @ r[0, c]), sk.heads[c]) for c in kids]), pivot="running")
    assert np.abs(dq.dq_apply(ident, sk.heads[fork] + 0.1) - dq.dq_apply(run, sk.heads[fork] + 0.1)).max() > 1e-3


def test_hybrid_chunks_frames_consistently(human, monkeypatch):
    model, _ = human
    poses = synthetic.random_poses(7, 19, seed=3)
    full = skinning.hybrid_skin(model, poses)
    monkeypatch.setattr(skinning, "FRAME_CHUNK", 3)
    np.testing.assert_array_equal(skinning.hybrid_skin(model, poses), full)


def test_affine_form_equals_hybrid_S15(human):
    model, poses = human
    A, b = skinning.affine_form(model, poses)
    posed = np.einsum("nvij,vj->nvi", A, model.rest_vertices) + b
    np.testing.assert_allclose(posed, skinning.hybrid_skin(model, poses), atol=1e-10)
    # T_T is not orthogonal when swing weights are fractional
    frac = (model.swing_weights > 0.05).any(axis=1) & (model.swing_weights < 0.95).all(axis=1)
    AtA = np.einsum("nvki,nvkj->nvij", A[:, frac], A[:, frac]) / poses.scales[:, None, None, None] ** 2
    assert np.abs(AtA - np.eye(3)).max() > 1e-3


def test_identity_pose_and_zero_weights_S7_S14(human):
    model, _ = human
    np.testing.assert_allclose(skinning.hybrid_skin(model, Poses.identity(2, 19)),
                               np.broadcast_to(model.rest_vertices, (2, model.num_vertices, 3)), atol=1e-15)


def test_binary_weights_give_rigid_fk_S16(human):
    model, poses = human
    rigid = Model(model.rest_vertices, model.faces, model.skeleton, model.anchor,
                  np.zeros_like(model.twist_weights), np.zeros_like(model.swing_weights))
    Rm, tm = kinematics.forward_kinematics(model.skeleton, poses)
    ref = np.einsum("nvij,vj->nvi", Rm[:, model.anchor], model.rest_vertices) + tm[:, model.anchor]
    np.testing.assert_allclose(skinning.hybrid_skin(rigid, poses), ref, atol=1e-13)
    # LBS with one-hot bone weights over the anchors is the same rigid FK
    onehot = np.eye(19)[model.anchor]
    np.testing.assert_allclose(skinning.lbs(model.rest_vertices, onehot, Rm, tm), ref, atol=1e-13)


def test_anchor_reexpression_invariance_S16():
    """Anchor a with zero weights == anchor parent(a) with twist = swing = 1 on joint a."""
    sk = synthetic.human_skeleton()
    poses = synthetic.random_poses(4, 19, seed=8, max_angle=3.0)
    V = 60
    rest = RNG.normal(size=(V, 3)) * 0.3 + [0, 0, 1.2]
    a = RNG.integers(1, 19, V).astype(np.int32)
    zero = np.zeros((V, 19), np.float32)
    m1 = Model(rest, np.zeros((0, 3), np.int32), sk, a, zero, zero)
    w = np.zeros((V, 19), np.float32)
    w[np.arange(V), a] = 1
    m2 = Model(rest, np.zeros((0, 3), np.int32), sk, sk.parents[a], w, w.copy())
    m1.validate()
    m2.validate()
    np.testing.assert_allclose(skinning.hybrid_skin(m1, poses), skinning.hybrid_skin(m2, poses), atol=1e-12)


def test_zero_weight_vertices_above_joint_do_not_move_S13(human):
    model, poses = human
    sk = model.skeleton
    j = sk.names.index("forearm.L")
    moved = Poses(poses.rotations.copy(), poses.translations, poses.scales)
    moved.rotations[:, j] = rot.rotvec_to_quat(RNG.normal(size=(len(poses), 3)))
    before, after = skinning.hybrid_skin(model, poses), skinning.hybrid_skin(model, moved)
    ancestors = {0}
    b = sk.parents[j]
    while b > 0:
        ancestors.add(b)
        b = sk.parents[b]
    unaffected = np.isin(model.anchor, list(ancestors)) & (model.twist_weights[:, j] == 0) & \
        (model.swing_weights[:, j] == 0)
    affected = model.anchor == j
    assert unaffected.sum() > 10 and affected.sum() > 2
    np.testing.assert_array_equal(after[:, unaffected], before[:, unaffected])
    assert np.abs(after[:, affected] - before[:, affected]).max() > 1e-3


# ---------------------------------------------------------------- tube: candy wrapper, swing = LBS

def tube_poses(rotvec_local):
    q = np.array([[[1.0, 0, 0, 0], rot.rotvec_to_quat(rotvec_local)]])
    return Poses(q, np.zeros((1, 3)), np.ones(1))


def lbs_tube(tube, poses, weights):
    Rm, tm = kinematics.forward_kinematics(tube.skeleton, poses)
    w = np.stack([1 - weights, weights], axis=1)
    return skinning.lbs(tube.rest_vertices, w, Rm, tm)


def test_candy_wrapper_S10():
    tube = synthetic.tube_model(swing_ramp=True)
    poses = tube_poses([0, np.pi, 0])                       # 180° twist about the bone's Y (world X)
    radius = np.linalg.norm(skinning.hybrid_skin(tube, poses)[0][:, 1:], axis=1)
    np.testing.assert_allclose(radius, 1.0, rtol=1e-9)
    lbs_r = np.linalg.norm(lbs_tube(tube, poses, tube.twist_weights[:, 1].astype(float))[0][:, 1:], axis=1)
    half = np.isclose(tube.twist_weights[:, 1], 0.5)
    assert half.sum() == 32 and lbs_r[half].max() < 1e-6
    # the twist is distributed: at weight 0.5 the ring turned by exactly 90°
    posed = skinning.hybrid_skin(tube, poses)[0][half]
    rest = tube.rest_vertices[half]
    cos = np.sum(posed[:, 1:] * rest[:, 1:], axis=1)
    np.testing.assert_allclose(cos, 0, atol=1e-12)


def test_swing_equals_lbs_S11_S9():
    tube = synthetic.tube_model(swing_ramp=True)
    poses = tube_poses([np.pi / 2, 0, 0])                  # 90° swing about the bone's X
    hyb = skinning.hybrid_skin(tube, poses)
    ref = lbs_tube(tube, poses, tube.swing_weights[:, 1].astype(float))
    np.testing.assert_allclose(hyb, ref, atol=1e-14)
    # pure twist makes the swing stage a no-op: swing weights do not matter
    twist = tube_poses([0, 1.3, 0])
    other = Model(tube.rest_vertices, tube.faces, tube.skeleton, tube.anchor, tube.twist_weights,
                  np.zeros_like(tube.swing_weights))
    np.testing.assert_allclose(skinning.hybrid_skin(tube, twist), skinning.hybrid_skin(other, twist), atol=1e-14)


def fork_model(n=24, width=1.2):
    """A "Y": a stem part and two branch parts meeting at one fork point; the surface is a grid of
    points around the fork.  Anchor = stem; the weight of the branches rises across y and is shared
    between left and right across x (smooth ramps of ``width`` metres)."""
    heads = np.array([[0, -1.0, 0], [0, 0, 0], [0, 0, 0]])
    tails = np.array([[0, 0, 0], [-0.7, 0.7, 0], [0.7, 0.7, 0]])
    sk = Skeleton(["stem", "left", "right"], [-1, 0, 0], heads, tails, frames_from_bones(heads, tails))
    g = np.linspace(-0.6, 0.6, n)
    X, Y = np.meshgrid(g, g, indexing="ij")
    verts = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)]).astype(np.int32)
    up = np.clip(verts[:, 1] / width + 0.5, 0, 1)
    side = np.clip(verts[:, 0] / width + 0.5, 0, 1)        # 0 = left, 1 = right, smooth in between
    return sk, verts, faces, up, side


def max_edge_stretch(posed, rest, faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    r = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    p = np.linalg.norm(posed[e[:, 0]] - posed[e[:, 1]], axis=1)
    return (p / r).max()


def fork_stretch(angle_scale):
    """Max edge stretch of the fork posed with both branches rotated (90° * angle_scale, opposite
    directions) for sibling (multi-joint) weights and for single-joint weights (nearer branch only)."""
    sk, verts, faces, up, side = fork_model()
    r = angle_scale * np.array([[[0, 0, 0], [1.2, 0.8, 0.6], [-1.2, -0.8, 0.6]]])
    poses = Poses(rot.rotvec_to_quat(r), np.zeros((1, 3)), np.ones(1))
    V = len(verts)
    anchor = np.zeros(V, np.int32)
    multi = np.zeros((V, 3), np.float32)
    multi[:, 1], multi[:, 2] = up * (1 - side), up * side
    single = np.zeros((V, 3), np.float32)
    right = side >= 0.5
    single[~right, 1], single[right, 2] = up[~right], up[right]
    stretch = {}
    for name, w in (("multi", multi), ("single", single)):
        m = Model(verts, faces, sk, anchor, w, w.copy())
        m.validate()
        stretch[name] = max_edge_stretch(skinning.hybrid_skin(m, poses)[0], verts, faces)
    return stretch


def test_fork_multi_joint_blending_has_no_cracks_S12():
    extreme = fork_stretch(1.0)                               # 90° each, opposite directions
    assert extreme["single"] > 10                             # a crack opens between the branches
    assert extreme["multi"] < extreme["single"] / 5
    moderate = fork_stretch(0.5)                              # 45° each
    assert moderate["multi"] < 1.5 < moderate["single"]


# ---------------------------------------------------------------- LBS / DQS references

def test_lbs_matches_loop_dense_and_sparse():
    import scipy.sparse as sp
    V, B, N = 40, 5, 3
    v = RNG.normal(size=(V, 3))
    w = RNG.uniform(0, 1, (V, B)) * (RNG.uniform(size=(V, B)) < 0.5)
    w /= np.maximum(w.sum(1, keepdims=True), 1) * 1.2
    Rm = rot.quat_to_matrix(rot.quat_normalize(RNG.normal(size=(N, B, 4)))) * 1.1
    tm = RNG.normal(size=(N, B, 3))
    ref = np.array([[(1 - w[i].sum()) * v[i] + sum(w[i, b] * (Rm[n, b] @ v[i] + tm[n, b]) for b in range(B))
                     for i in range(V)] for n in range(N)])
    np.testing.assert_allclose(skinning.lbs(v, w, Rm, tm), ref, atol=1e-13)
    np.testing.assert_allclose(skinning.lbs(v, sp.csr_matrix(w), Rm, tm), ref, atol=1e-13)


@pytest.mark.parametrize("align", ["running", "max"])
def test_dqs_matches_per_vertex_reference(align):
    import scipy.sparse as sp
    V, B, N = 30, 4, 2
    v = RNG.normal(size=(V, 3))
    w = RNG.uniform(0, 1, (V, B)) * (RNG.uniform(size=(V, B)) < 0.6)
    w[0] = 0                                                   # a vertex without weights stays put
    R = rot.quat_to_matrix(rot.quat_normalize(RNG.normal(size=(N, B, 4))))
    s = 1.3
    tm = RNG.normal(size=(N, B, 3))
    out = skinning.dqs(v, w, s * R, tm, align=align)
    ref = np.empty_like(out)
    flips = 0
    for n in range(N):
        d = [dq.dq_from_rigid(R[n, b], tm[n, b]) for b in range(B)]
        for i in range(V):
            if w[i].sum() == 0:
                ref[n, i] = v[i]
                continue
            wi = w[i] / w[i].sum()
            acc = np.zeros(8)
            piv = rot.quat_canonical(d[int(np.argmax(wi))][:4])
            for b in range(B):                                 # Blender: ascending bone order
                if wi[b] == 0:
                    continue
                pivot = acc[:4] if align == "running" else piv
                sign = -1.0 if d[b][:4] @ pivot < 0 else 1.0
                flips += sign < 0
                acc += wi[b] * sign * d[b]
            ref[n, i] = dq.dq_apply(acc, s * v[i])
    assert flips > 0                                           # the alignment matters in this data
    np.testing.assert_allclose(out, ref, atol=1e-12)
    csr = sp.csr_matrix(w)
    np.testing.assert_allclose(skinning.dqs(v, csr, s * R, tm, align=align), ref, atol=1e-12)
    stored_zero = csr.copy()
    stored_zero.data[0] = 0.0                                  # an explicitly stored zero weight
    skinning.dqs(v, stored_zero, s * R, tm, align=align)
    assert stored_zero.nnz == csr.nnz                          # the caller's matrix is not modified


def test_dqs_is_rigid_for_one_bone_and_keeps_tube_radius():
    tube = synthetic.tube_model()
    poses = tube_poses([0, np.pi * 0.9, 0])
    Rm, tm = kinematics.forward_kinematics(tube.skeleton, poses)
    w = np.stack([1 - tube.twist_weights[:, 1], tube.twist_weights[:, 1]], 1).astype(float)
    r = np.linalg.norm(skinning.dqs(tube.rest_vertices, w, Rm, tm)[0][:, 1:], axis=1)
    np.testing.assert_allclose(r, 1, rtol=1e-12)


# ---------------------------------------------------------------- groups reuse and bad input

def test_reused_groups_give_identical_results(human):
    model, poses = human
    g = skinning.AnchorGroups(model)
    np.testing.assert_array_equal(skinning.hybrid_skin(model, poses, g), skinning.hybrid_skin(model, poses))
    A1, b1 = skinning.affine_form(model, poses, g)
    A2, b2 = skinning.affine_form(model, poses)
    np.testing.assert_array_equal(A1, A2)
    np.testing.assert_array_equal(b1, b2)
    other = synthetic.random_model(50, seed=3)
    from articula.solver.errors import ArticulaInputError
    with pytest.raises(ArticulaInputError, match="groups: built for 120 vertices"):
        skinning.hybrid_skin(other, poses, g)


def test_bad_shapes_raise_input_errors(human):
    from articula.solver.errors import ArticulaInputError
    model, poses = human
    with pytest.raises(ArticulaInputError, match=r"pose_rotations: expected shape \(N, 19, 4\)"):
        skinning.hybrid_skin(model, Poses.identity(2, 5))
    bad = Poses(poses.rotations, poses.translations[:1], poses.scales)
    with pytest.raises(ArticulaInputError, match="pose_translations"):
        skinning.affine_form(model, bad)
    Rm, tm = kinematics.forward_kinematics(model.skeleton, poses)
    with pytest.raises(ArticulaInputError, match=r"weights: expected shape \(120, 19\)"):
        skinning.lbs(model.rest_vertices, model.swing_weights[:, :4], Rm, tm)
    with pytest.raises(ArticulaInputError, match="tm: expected"):
        skinning.dqs(model.rest_vertices, model.swing_weights, Rm, tm[:, :3])
    with pytest.raises(ArticulaInputError, match="vertices: expected"):
        skinning.lbs(model.rest_vertices[:, :2], model.swing_weights, Rm, tm)


def test_zero_frames_give_empty_results(human):
    model, _ = human
    none = Poses.identity(0, 19)
    assert skinning.hybrid_skin(model, none).shape == (0, 120, 3)
    A, b = skinning.affine_form(model, none)
    assert A.shape == (0, 120, 3, 3) and b.shape == (0, 120, 3)


def _explicit_hamilton(a, b):
    """Hamilton product of two quaternions (w, x, y, z), written out for the test."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def _explicit_twist_blend(x, heads, axes, angles, weights, neutral_weight):
    """Blender's Preserve Volume blend of rotations about ``axes`` (K, 3) through ``heads`` (K, 3) by
    ``angles`` (K,) with ``weights`` (K,), written out: the neutral (identity, weight ``neutral_weight``)
    starts the running sum, each dual quaternion is negated when its real part points away from the sum
    so far, the sum is normalised and applied to ``x`` (3,).  Returns (posed x, flipped flags)."""
    acc_r = np.array([neutral_weight, 0.0, 0.0, 0.0])
    acc_d = np.zeros(4)
    flipped = []
    for h, u, angle, w in zip(heads, axes, angles, weights):
        q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * u])
        R = rot.quat_to_matrix(q)
        d = 0.5 * _explicit_hamilton(np.concatenate([[0.0], h - R @ h]), q)
        sign = -1.0 if (q @ acc_r < 0 and w > 0) else 1.0
        flipped.append(sign < 0)
        acc_r, acc_d = acc_r + sign * w * q, acc_d + sign * w * d
    n = np.linalg.norm(acc_r)
    qr, qd = acc_r / n, acc_d / n
    t = 2.0 * _explicit_hamilton(qd, qr * np.array([1.0, -1.0, -1.0, -1.0]))[1:]
    return rot.quat_to_matrix(qr) @ x + t, flipped


def test_twist_hemisphere_rule_starts_from_the_neutral_remainder_weight():
    """Two opposite children of a fork (the collarbones) twisted together, chosen so that the flip of the
    second child depends on the neutral's weight 1 − Σw at the start of the running sum: frame 0
    (100° each, w = 0.3 + 0.3) does not flip with the remainder 0.4 but would without the neutral;
    frame 1 (120° each, w = 0.45 + 0.45) flips with the remainder 0.1 but would not with a neutral of
    weight 1.  hybrid_skin and dualquat.dlb ("running") must equal the blend written out here."""
    model = synthetic.random_model(200, seed=4)
    sk = model.skeleton
    fork, kids = min(((a, pair) for a in range(sk.num_bones) for pair in
                      [(c, d) for c in sk.children(a) for d in sk.children(a) if c < d]),
                     key=lambda ap: sk.frames[ap[1][0], :, 1] @ sk.frames[ap[1][1], :, 1])
    kids = list(kids)
    sel = np.flatnonzero(model.anchor == fork)
    half_a, half_b = sel[: len(sel) // 2], sel[len(sel) // 2:]
    assert len(half_a) and len(half_b)
    wt = np.zeros_like(model.twist_weights)
    wt[half_a[:, None], kids] = 0.3
    wt[half_b[:, None], kids] = 0.45
    model = Model(model.rest_vertices, model.faces, sk, model.anchor, wt, np.zeros_like(wt))
    angles = np.radians([100.0, 120.0])
    r = np.zeros((2, sk.num_bones, 3))
    r[0, kids, 1], r[1, kids, 1] = angles[0], angles[1]       # twist about each child's own Y axis
    poses = Poses(rot.rotvec_to_quat(r), np.zeros((2, 3)), np.ones(2))
    got = skinning.hybrid_skin(model, poses)

    heads, axes = sk.heads[kids], sk.frames[kids][:, :, 1]
    for n, (half, w, discriminating_neutral) in enumerate([(half_a, 0.3, 0.0), (half_b, 0.45, 1.0)]):
        w = float(np.float32(w))                               # the model stores weights as float32
        weights = np.array([w, w])
        # the case is built so the neutral's weight decides the second child's flip
        _, flips_true = _explicit_twist_blend(np.zeros(3), heads, axes, [angles[n]] * 2, weights, 1 - 2 * w)
        _, flips_wrong = _explicit_twist_blend(np.zeros(3), heads, axes, [angles[n]] * 2, weights,
                                               discriminating_neutral)
        assert flips_true[1] != flips_wrong[1] and not flips_true[0]
        expected = np.array([_explicit_twist_blend(model.rest_vertices[v], heads, axes, [angles[n]] * 2,
                                                   weights, 1 - 2 * w)[0] for v in half])
        np.testing.assert_allclose(got[n, half], expected, rtol=0, atol=1e-12)
        wrong = np.array([_explicit_twist_blend(model.rest_vertices[v], heads, axes, [angles[n]] * 2,
                                                weights, discriminating_neutral)[0] for v in half])
        assert np.abs(wrong - expected).max() > 1e-3              # the neutral's weight matters here
        dqs_ = np.stack([dq.dq_rotation_about(rot.rotvec_to_quat(angles[n] * u), h) for u, h in zip(axes, heads)])
        blended = dq.dlb(weights, dqs_, pivot="running")
        np.testing.assert_allclose(dq.dq_apply(blended, model.rest_vertices[half]), expected, rtol=0, atol=1e-12)
    flips = skinning.twist_flips(model, poses)
    assert flips[1, half_b].all() and not flips[0, half_a].any()
