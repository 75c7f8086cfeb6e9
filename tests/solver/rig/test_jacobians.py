"""Analytic Jacobians of the hybrid skin against central finite differences."""
import numpy as np
import pytest

from articula.solver.rig import jacobians
from articula.solver.rig import skinning
from articula.sample_scenes import synthetic
from articula.solver.rig.model import Model, Poses, Skeleton

H = 1e-6


@pytest.fixture(scope="module")
def case():
    model = synthetic.random_model(60, seed=4)
    # make the weights large so every path (twist DLB, swing LBS, chain) matters
    model.twist_weights *= 2.5
    model.swing_weights *= 2.5
    s = np.maximum(model.twist_weights.sum(1), model.swing_weights.sum(1))
    scale = np.where(s > 1, 1 / np.maximum(s, 1e-9), 1).astype(np.float32)
    model.twist_weights *= scale[:, None]
    model.swing_weights *= scale[:, None]
    model.validate()
    poses = synthetic.random_poses(2, 19, seed=6, max_angle=2.0)
    return model, poses


def rel_err(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-12)


def fd_pose(model, poses, cols):
    N = len(poses)
    P = jacobians.pose_layout(model.skeleton.num_bones)["size"]
    out = []
    for j in cols:
        d = np.zeros((N, P))
        d[:, j] = H
        plus = skinning.hybrid_skin(model, jacobians.apply_pose_increment(poses, d))
        minus = skinning.hybrid_skin(model, jacobians.apply_pose_increment(poses, -d))
        out.append((plus - minus) / (2 * H))
    return np.stack(out, axis=-1)


def test_pose_jacobian_matches_central_differences(case):
    model, poses = case
    posed, J = jacobians.pose_jacobian(model, poses)
    np.testing.assert_allclose(posed, skinning.hybrid_skin(model, poses), atol=1e-12)
    P = J.shape[-1]
    assert P == 4 + 3 * 19
    fd = fd_pose(model, poses, range(P))
    assert rel_err(J, fd) < 1e-6
    # every bone's block is exercised (non-zero somewhere) and columns are individually right
    for b in range(19):
        sl = jacobians.pose_layout(19)["rotation"](b)
        assert np.abs(J[..., sl]).max() > 1e-3
        assert rel_err(J[..., sl], fd[..., sl]) < 1e-6, b


def test_pose_jacobian_child_blocks_are_not_trivial(case):
    """The twist/swing blocks of blended children differ from the rigid-chain formula: dropping the
    swing/twist split (treating the child as a chain bone) gives a wrong Jacobian, so the FD test
    above can fail."""
    model, poses = synthetic.random_model(200, seed=4), case[1]
    posed, J = jacobians.pose_jacobian(model, poses)
    bt = jacobians._pose_bone_terms(model.skeleton, poses)
    c = model.skeleton.names.index("forearm.L")
    w = np.minimum(model.twist_weights[:, c], model.swing_weights[:, c])
    rows = np.flatnonzero((model.anchor == model.skeleton.parents[c]) & (w > 0.2) & (w < 0.8))
    assert len(rows)
    wrong = -jacobians._skew(posed[:, rows] - bt["p"][:, c, None]) @ bt["K"][:, c, None]
    sl = jacobians.pose_layout(19)["rotation"](c)
    assert rel_err(wrong, J[:, rows][..., sl]) > 0.05


def test_joint_jacobian_matches_central_differences(case):
    model, poses = case
    posed, J = jacobians.joint_jacobian(model, poses)
    sk = model.skeleton
    fd = np.zeros_like(J)
    for j in range(3 * sk.num_bones):
        out = []
        for sign in (1, -1):
            heads = sk.heads.copy()
            heads[j // 3, j % 3] += sign * H
            moved = Skeleton(sk.names, sk.parents, heads, sk.tails, sk.frames)
            m = Model(model.rest_vertices, model.faces, moved, model.anchor, model.twist_weights,
                      model.swing_weights)
            out.append(skinning.hybrid_skin(m, poses))
        fd[..., j] = (out[0] - out[1]) / (2 * H)
    assert rel_err(J, fd) < 1e-6
    np.testing.assert_allclose(posed, skinning.hybrid_skin(model, poses), atol=1e-12)


def test_jacobian_near_identity_and_pure_twist():
    """Small rotations (near the exp/log branch points) and a pure twist pose."""
    model = synthetic.random_model(40, seed=9)
    B = 19
    for r in (1e-7, 0.0):
        rv = np.zeros((1, B, 3))
        rv[0, :, 1] = r
        from articula.solver.geometry.rotations import rotvec_to_quat
        poses = Poses(rotvec_to_quat(rv), np.zeros((1, 3)), np.ones(1))
        _, J = jacobians.pose_jacobian(model, poses)
        fd = fd_pose(model, poses, range(J.shape[-1]))
        assert rel_err(J, fd) < 1e-6


def test_sparse_conversion_and_increment_layout(case):
    model, poses = case
    _, J = jacobians.pose_jacobian(model, poses)
    S = jacobians.to_sparse(J[0])
    assert S.shape == (3 * model.num_vertices, J.shape[-1])
    np.testing.assert_array_equal(S.toarray(), J[0].reshape(3 * model.num_vertices, -1))
    # vertices touch only t, s, their chain and their anchor's children
    assert S.nnz < 0.6 * S.shape[0] * S.shape[1]
    d = np.zeros((len(poses), J.shape[-1]))
    d[:, 0:3] = [0.1, -0.2, 0.3]
    d[:, 3] = 0.05
    moved = jacobians.apply_pose_increment(poses, d)
    np.testing.assert_allclose(moved.translations - poses.translations, [[0.1, -0.2, 0.3]] * 2)
    np.testing.assert_allclose(moved.scales - poses.scales, 0.05)
    np.testing.assert_allclose(moved.rotations, poses.rotations)


def test_gauss_newton_recovers_pose():
    """A few Gauss–Newton steps with the analytic Jacobian recover a random pose from posed vertices
    (the Jacobian is usable by a solver, not only correct at one point)."""
    model = synthetic.random_model(400, seed=12)
    target = synthetic.random_poses(1, 19, seed=13, max_angle=0.6)
    goal = skinning.hybrid_skin(model, target)
    poses = Poses.identity(1, 19)
    for _ in range(8):
        posed, J = jacobians.pose_jacobian(model, poses)
        A = J[0].reshape(-1, J.shape[-1])
        r = (posed - goal)[0].ravel()
        step = np.linalg.lstsq(A, -r, rcond=None)[0]
        poses = jacobians.apply_pose_increment(poses, step[None])
    assert np.abs(skinning.hybrid_skin(model, poses) - goal).max() < 1e-9


def test_sign_of_quaternions_does_not_matter(case):
    model, poses = case
    flipped = Poses(-poses.rotations, poses.translations, poses.scales)
    p1, J1 = jacobians.pose_jacobian(model, poses)
    p2, J2 = jacobians.pose_jacobian(model, flipped)
    np.testing.assert_allclose(p2, p1, atol=1e-13)
    np.testing.assert_allclose(J2, J1, atol=1e-12)


def test_bad_increment_shape(case):
    from articula.solver.errors import ArticulaInputError
    _, poses = case
    with pytest.raises(ArticulaInputError, match=r"delta: expected shape \(2, 61\)"):
        jacobians.apply_pose_increment(poses, np.zeros((2, 60)))


def test_frame_jacobian_matches_central_differences(case):
    model, poses = case
    sk = model.skeleton
    posed, J = jacobians.frame_jacobian(model, poses)
    np.testing.assert_allclose(posed, skinning.hybrid_skin(model, poses), atol=1e-12)
    fd = np.zeros_like(J)
    for j in range(3 * sk.num_bones):
        out = []
        for sign in (1, -1):
            omega = np.zeros((sk.num_bones, 3))
            omega[j // 3, j % 3] = sign * H
            moved, p = jacobians.apply_frame_increment(sk, poses, omega)
            m = Model(model.rest_vertices, model.faces, moved, model.anchor, model.twist_weights,
                      model.swing_weights)
            out.append(skinning.hybrid_skin(m, p))
        fd[..., j] = (out[0] - out[1]) / (2 * H)
    assert rel_err(J, fd) < 1e-6
    assert np.abs(J).max() > 1e-2                       # the split really moves blended vertices
    np.testing.assert_array_equal(J[..., 0:3], 0)       # the root frame is a gauge freedom


def test_frame_increment_keeps_world_rotations(case):
    from articula.solver.rig import kinematics
    model, poses = case
    omega = np.random.default_rng(1).normal(size=(19, 3)) * 0.3
    sk, p = jacobians.apply_frame_increment(model.skeleton, poses, omega)
    sk.validate()
    np.testing.assert_allclose(kinematics.world_rotations(sk, p.rotations),
                               kinematics.world_rotations(model.skeleton, poses.rotations), atol=1e-12)
    rigid = Model(model.rest_vertices, model.faces, sk, model.anchor, np.zeros_like(model.twist_weights),
                  np.zeros_like(model.swing_weights))
    orig = Model(model.rest_vertices, model.faces, model.skeleton, model.anchor, rigid.twist_weights,
                 rigid.swing_weights)
    np.testing.assert_allclose(skinning.hybrid_skin(rigid, p), skinning.hybrid_skin(orig, poses), atol=1e-12)


def test_jacobians_carry_the_flipped_twist_hemisphere():
    """At a pose where the running-sum rule flips a twist (two opposite collarbones twisted 170°),
    the pose and joint Jacobians still match central differences (the signs are locally constant)."""
    sk = synthetic.human_skeleton()
    model = synthetic.random_model(80, seed=9)
    fork, kids = min(((a, (c, d)) for a in range(sk.num_bones) for c in sk.children(a)
                      for d in sk.children(a) if c < d),
                     key=lambda ap: sk.frames[ap[1][0], :, 1] @ sk.frames[ap[1][1], :, 1])
    wt = np.zeros_like(model.twist_weights)
    sel = np.flatnonzero(model.anchor == fork)
    wt[sel, kids[0]] = wt[sel, kids[1]] = 0.35
    model = Model(model.rest_vertices, model.faces, sk, model.anchor, wt, model.swing_weights)
    poses = synthetic.random_poses(1, 19, seed=3, max_angle=0.3)
    r = np.zeros((1, 19, 3))
    r[0, list(kids), 1] = np.radians(170.0)
    from articula.solver.geometry import rotations as rot
    poses.rotations[0, list(kids)] = rot.rotvec_to_quat(r[0, list(kids)])
    assert skinning.twist_flips(model, poses)[0, sel].any()
    _, J = jacobians.pose_jacobian(model, poses)
    cols = [c for b in kids for c in range(*jacobians.pose_layout(19)["rotation"](b).indices(J.shape[-1]))]
    assert rel_err(J[..., cols], fd_pose(model, poses, cols)) < 1e-6
    _, Jh = jacobians.joint_jacobian(model, poses)
    for b in kids:
        fd = []
        for i in range(3):
            heads = sk.heads.copy()
            heads[b, i] += H
            plus = skinning.hybrid_skin(Model(model.rest_vertices, model.faces, Skeleton(
                sk.names, sk.parents, heads, sk.tails + (heads - sk.heads), sk.frames), model.anchor, wt,
                model.swing_weights), poses)
            heads[b, i] -= 2 * H
            minus = skinning.hybrid_skin(Model(model.rest_vertices, model.faces, Skeleton(
                sk.names, sk.parents, heads, sk.tails + (heads - sk.heads), sk.frames), model.anchor, wt,
                model.swing_weights), poses)
            fd.append((plus - minus) / (2 * H))
        assert rel_err(Jh[..., 3 * b:3 * b + 3], np.stack(fd, -1)) < 1e-6


def test_dq_apply_jacobian_equals_central_differences():
    """∂ dq_apply(b, x) / ∂b for un-normalised, non-rigid blends b (any dual part), against central
    differences, over a batch with broadcast points."""
    from articula.solver.geometry.dualquat import dq_apply
    rng = np.random.default_rng(11)
    b = rng.normal(size=(3, 5, 8))
    x = rng.normal(size=(5, 3))
    J = jacobians._dq_apply_jacobian(b, x)
    assert J.shape == (3, 5, 3, 8)
    h = 1e-6
    for j in range(8):
        e = np.zeros(8)
        e[j] = h
        fd = (dq_apply(b + e, x) - dq_apply(b - e, x)) / (2 * h)
        assert np.allclose(J[..., j], fd, rtol=1e-7, atol=1e-7), j
