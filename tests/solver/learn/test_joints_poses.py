"""G9 (joints + poses by Levenberg–Marquardt), G10 (symmetry), G11 (Schur complement = dense solve)."""
import copy

import numpy as np

from articula.solver.fit.least_squares import GainRatioDamping
from articula.solver.learn.joints_poses import (JointPoseProblem, apply_increment, dense_normal_blocks,
                                                normal_equation_blocks, optimise_joints_and_poses, posed_jacobians,
                                                posed_jacobians_fd, relative_joint_prior, schur_solve, sizes,
                                                symmetry_residuals)
from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.skinning import hybrid_skin

from articula.sample_scenes.tube_scans import hybrid_truth

WEIGHTED = [1, 3, 5, 6, 7]          # bones with fractional weights: their twist axis is identifiable


def _perturbed(model, poses, seed=0, dh=0.02, deg=10.0, dpose=0.05):
    rng = np.random.default_rng(seed)
    B, M = model.skeleton.num_bones, len(poses)
    n_s, n_o = sizes(B)
    ds = np.zeros((B - 1, 5))
    ds[:, :3] = rng.uniform(-dh, dh, (B - 1, 3))
    ds[:, 3:] = rng.uniform(-1, 1, (B - 1, 2)) * np.radians(deg) / np.sqrt(2)
    sk, p = apply_increment(model.skeleton, poses, ds.ravel(), dpose * rng.normal(size=(M, n_o)))
    m = copy.copy(model)
    m.skeleton = sk
    return m, p


def _angles(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a.frames[:, :, 1] * b.frames[:, :, 1], axis=1), -1, 1)))


def test_apply_increment_keeps_world_rotations_when_only_the_axis_changes():
    model, poses, _ = hybrid_truth(3)
    n_s, n_o = sizes(8)
    ds = np.zeros((7, 5))
    ds[:, 3:] = 0.2
    sk, p = apply_increment(model.skeleton, poses, ds.ravel(), np.zeros((3, n_o)))
    from articula.solver.rig.kinematics import forward_kinematics
    R0, t0 = forward_kinematics(model.skeleton, poses)
    R1, t1 = forward_kinematics(sk, p)
    assert np.abs(R0 - R1).max() < 1e-12 and np.abs(t0 - t1).max() < 1e-12
    sk.validate()
    assert _angles(sk, model.skeleton)[1:].min() > 10


def test_posed_jacobian_against_closed_forms():
    model, poses, _ = hybrid_truth(3)
    Js, Jo = posed_jacobians(model, poses)
    V, B = model.num_vertices, 8
    # translation columns: identity for every vertex of every scan
    Jt = Jo[:, :, 3 * B:].reshape(3, V, 3, 3)
    assert np.abs(Jt - np.eye(3)).max() < 1e-8
    # rest scan (identity pose), rigid vertex of bone b, local rotation axis i: (F_b e_i) x (x - chain centre)
    sk, x = model.skeleton, model.rest_vertices
    rigid = (model.twist_weights.sum(1) == 0) & (model.swing_weights.sum(1) == 0)
    for b in (0, 3, 6):
        rows = np.flatnonzero(rigid & (model.anchor == b))
        chain = [b]
        while sk.parents[chain[-1]] >= 0:
            chain.append(int(sk.parents[chain[-1]]))
        for c in chain:
            for i in range(3):
                want = np.cross(sk.frames[c][:, i], x[rows] - sk.heads[c])
                got = Jo[0].reshape(V, 3, -1)[rows, :, 3 * c + i]
                assert np.abs(got - want).max() < 1e-8
    # a head moves nothing in the rest pose (rotation about it is identity)
    assert np.abs(Js[0]).max() < 1e-8



def test_analytic_jacobian_equals_finite_differences():
    """G9: the analytic Jacobian (solver.rig.jacobians in this module's layout) vs central differences."""
    model, poses, _ = hybrid_truth(3)
    Js, Jo = posed_jacobians(model, poses)
    Js_fd, Jo_fd = posed_jacobians_fd(model, poses)
    scale = max(np.abs(Js).max(), np.abs(Jo).max())
    assert np.abs(Js - Js_fd).max() < 1e-5 * scale
    assert np.abs(Jo - Jo_fd).max() < 1e-5 * scale
    assert np.abs(Js[:, :, 3::5]).max() > 1e-3                 # the frame columns are not trivially 0


def test_schur_complement_equals_dense_solve():
    rng = np.random.default_rng(3)
    M, n_s, n_o = 4, 6, 5
    J = rng.normal(size=(M * 9 + 7, n_s + M * n_o))
    mask = np.zeros_like(J, dtype=bool)                       # arrow-head pattern
    mask[:, :n_s] = True
    for m in range(M):
        mask[m * 9:(m + 1) * 9, n_s + m * n_o:n_s + (m + 1) * n_o] = True
    J = np.where(mask, J, 0.0)
    H = J.T @ J + 0.1 * np.eye(J.shape[1])
    g = rng.normal(size=J.shape[1])
    H_ss = H[:n_s, :n_s]
    H_so = np.stack([H[:n_s, n_s + m * n_o:n_s + (m + 1) * n_o] for m in range(M)])
    H_oo = np.stack([H[n_s + m * n_o:n_s + (m + 1) * n_o, n_s + m * n_o:n_s + (m + 1) * n_o] for m in range(M)])
    x_s, x_o = schur_solve(H_ss, H_so, H_oo, g[:n_s], g[n_s:].reshape(M, n_o))
    dense = np.linalg.solve(H, g)
    assert np.abs(np.concatenate([x_s, x_o.ravel()]) - dense).max() < 1e-8


def test_dense_normal_blocks_equal_dense_products():
    model, poses, scans = hybrid_truth(2)
    L = uniform_laplacian(model.faces, model.num_vertices)
    Js, Jo = posed_jacobians(model, poses)
    rng = np.random.default_rng(0)
    rd, rl = rng.normal(size=(2, 2, model.num_vertices, 3))
    H_ss, H_so, H_oo, g_s, g_o = dense_normal_blocks(Js, Jo, rd, rl, L, 5.0)
    Lk = np.kron(L.toarray(), np.eye(3))
    J1 = np.hstack([Js[1], Jo[1]])
    H1 = J1.T @ J1 + 5.0 * (Lk @ J1).T @ (Lk @ J1)
    n_s = Js.shape[2]
    assert np.allclose(H_so[1], H1[:n_s, n_s:], atol=1e-9) and np.allclose(H_oo[1], H1[n_s:, n_s:], atol=1e-9)
    assert np.allclose(g_o[1], Jo[1].T @ rd[1].ravel() + 5.0 * (Lk @ Jo[1]).T @ rl[1].ravel(), atol=1e-9)


def _einsum_blocks(Js, Jo, rd, rl, L, alpha):
    """The normal-equation blocks by einsum on the dense Jacobian and an explicit (3V, 3V) Laplacian."""
    import scipy.sparse as sp
    Lk = sp.kron(L, sp.identity(3), format="csr")
    LJs, LJo = np.stack([Lk @ j for j in Js]), np.stack([Lk @ j for j in Jo])
    M = len(Js)
    rd, rl = rd.reshape(M, -1), rl.reshape(M, -1)
    return (np.einsum("mri,mrj->ij", Js, Js) + alpha * np.einsum("mri,mrj->ij", LJs, LJs),
            np.einsum("mri,mrj->mij", Js, Jo) + alpha * np.einsum("mri,mrj->mij", LJs, LJo),
            np.einsum("mri,mrj->mij", Jo, Jo) + alpha * np.einsum("mri,mrj->mij", LJo, LJo),
            np.einsum("mri,mr->i", Js, rd) + alpha * np.einsum("mri,mr->i", LJs, rl),
            np.einsum("mri,mr->mi", Jo, rd) + alpha * np.einsum("mri,mr->mi", LJo, rl))


def test_compact_blocks_equal_the_einsum_reference():
    """normal_equation_blocks (per-anchor-group Gram matrices of factored Jacobians, Laplacian rows split at
    the group borders, chunks of scans) = the einsum formulation on the dense Jacobian."""
    from articula.solver.learn.joints_poses import scan_chunk
    model, poses, scans = hybrid_truth(3)
    L = uniform_laplacian(model.faces, model.num_vertices)
    obj = RigObjective(scans, L, 5.0)
    start, p0 = _perturbed(model, poses, seed=4)
    Js, Jo = posed_jacobians(start, p0)
    rd, rl = obj.residuals(hybrid_skin(start, p0))
    ref = _einsum_blocks(Js, Jo, rd, rl, L, 5.0)
    for chunk in (1, 2, 3):
        got = normal_equation_blocks(start, p0, obj, chunk=chunk)
        for want, have in zip(ref, got):
            assert have.shape == want.shape
            assert np.abs(have - want).max() < 1e-11 * np.abs(want).max()
    assert scan_chunk(13380) == 4 and scan_chunk(754) == 71 and scan_chunk(10 ** 6) == 1
    own = normal_equation_blocks(start, p0, obj, own_only=True)
    assert np.abs(own[2] - ref[2]).max() < 1e-11 * np.abs(ref[2]).max()
    assert np.abs(own[4] - ref[4]).max() < 1e-11 * np.abs(ref[4]).max()


def test_lm_recovers_perturbed_joints_and_q_is_monotone():
    model, poses, scans = hybrid_truth(8)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start, p0 = _perturbed(model, poses)
    problem = JointPoseProblem(obj)
    q0 = problem.value(start, p0)
    fitted, p1, log = optimise_joints_and_poses(start, p0, problem, iterations=10)
    assert log and log[0] < q0 and all(b <= a for a, b in zip(log, log[1:]))
    assert np.linalg.norm(fitted.skeleton.heads - model.skeleton.heads, axis=1).max() < 1e-3
    assert _angles(fitted.skeleton, model.skeleton)[WEIGHTED].max() < 0.5
    assert np.abs(hybrid_skin(fitted, p1) - scans).max() < 1e-6


def test_symmetry_residual_zero_iff_equal_lengths_for_any_direction():
    model, _, _ = hybrid_truth(2)
    sk = copy.deepcopy(model.skeleton)
    pairs = [(2, 3, 4, 5)]                                     # upper arms: shoulder -> elbow
    r, J = symmetry_residuals(sk, pairs)
    assert abs(r[0]) < 1e-15
    sk.heads[5] = sk.heads[4] + 0.3 * np.array([0.0, 0.6, -0.8])   # same length, another direction
    assert abs(symmetry_residuals(sk, pairs)[0][0]) < 1e-15
    sk.heads[5] = sk.heads[4] + 0.31 * np.array([0.0, 0.6, -0.8])
    assert np.isclose(symmetry_residuals(sk, pairs)[0][0], -0.01)
    # Jacobian vs central differences
    r0, J = symmetry_residuals(sk, pairs)
    n_s, _ = sizes(8)
    for j in range(n_s):
        if j % 5 >= 3:
            continue
        e = np.zeros((7, 5)).ravel()
        e[j] = 1e-6
        b = 1 + j // 5
        sp_, sm_ = copy.deepcopy(sk), copy.deepcopy(sk)
        sp_.heads[b] += e.reshape(7, 5)[b - 1, :3]
        sm_.heads[b] -= e.reshape(7, 5)[b - 1, :3]
        fd = (symmetry_residuals(sp_, pairs)[0] - symmetry_residuals(sm_, pairs)[0]) / 2e-6
        assert np.allclose(fd, J[:, j], atol=1e-8)


def test_symmetry_term_equalises_bone_lengths():
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start, p0 = _perturbed(model, poses, seed=2)
    pairs = [(2, 3, 4, 5)]
    problem = JointPoseProblem(obj, pairs, lam=1e10)
    fitted, _, log = optimise_joints_and_poses(start, p0, problem, iterations=8)
    assert all(b <= a for a, b in zip(log, log[1:]))
    assert abs(symmetry_residuals(fitted.skeleton, pairs)[0][0]) < 1e-7       # < 1e-4 mm


def test_joint_prior_gradient_and_effect():
    """κ Q_prior: its normal-equation gradient is half the finite-difference gradient of the value; with a large
    κ the LM keeps perturbed joints at the prior, with κ = 0 it recovers the true ones."""
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start, p0 = _perturbed(model, poses, seed=3)
    prior = start.skeleton.heads + 0.01
    problem = JointPoseProblem(obj, prior_heads=prior, kappa=50.0)
    n_s, _ = sizes(8)
    H, g = problem.add_shared_terms(start.skeleton, np.zeros((n_s, n_s)), np.zeros(n_s))
    for j in range(n_s):
        e = np.zeros(n_s)
        e[j] = 1e-6
        plus, _ = apply_increment(start.skeleton, p0, e, np.zeros((len(p0), sizes(8)[1])))
        minus, _ = apply_increment(start.skeleton, p0, -e, np.zeros((len(p0), sizes(8)[1])))
        fd = (problem.shared_value(plus) - problem.shared_value(minus)) / 2e-6
        assert abs(fd - 2 * g[j]) < 1e-6
        assert H[j, j] == (50.0 if j % 5 < 3 else 0.0)
    stiff = JointPoseProblem(obj, prior_heads=start.skeleton.heads, kappa=1e9)
    held, _, log = optimise_joints_and_poses(start, p0, stiff, iterations=6)
    assert log and all(b <= a for a, b in zip(log, log[1:]))
    assert np.abs(held.skeleton.heads - start.skeleton.heads).max() < 1e-5
    free, _, _ = optimise_joints_and_poses(start, p0, JointPoseProblem(obj), iterations=6)
    assert np.linalg.norm(free.skeleton.heads - model.skeleton.heads, axis=1).max() < 1e-3
    kappa = relative_joint_prior(start, p0, obj, 1.0)                  # ρ × mean head curvature, per joint
    H_ss = dense_normal_blocks(*posed_jacobians(start, p0), *obj.residuals(hybrid_skin(start, p0)), obj.L, 100.0)[0]
    assert np.allclose(kappa, [np.trace(H_ss[5 * b:5 * b + 3, 5 * b:5 * b + 3]) / 3 for b in range(7)], rtol=1e-9)


def test_pose_only_blocks_equal_the_full_blocks():
    """The warm-up rounds (joints fixed) build only the per-scan blocks: the same as in the full system."""
    model, poses, scans = hybrid_truth(3)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start, p0 = _perturbed(model, poses)
    full = normal_equation_blocks(start, p0, obj)
    own = normal_equation_blocks(start, p0, obj, own_only=True)
    assert own[0].shape == (0, 0) and own[3].shape == (0,) and own[1].shape[1] == 0
    # the same sums over differently sized blocks: equal to rounding (BLAS kernels differ between CPUs)
    for x, y in ((own[2], full[2]), (own[4], full[4])):
        assert np.allclose(x, y, rtol=1e-13, atol=1e-13 * np.abs(y).max())


def test_damping_carries_over():
    """A damping object passed to the LM ends where the LM ended, and a second call started from it continues
    to lower Q (the rule itself: tests/solver/fit/test_least_squares.py)."""
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start, p0 = _perturbed(model, poses, seed=4)
    damping = GainRatioDamping()
    problem = JointPoseProblem(obj)
    mid, p1, log1 = optimise_joints_and_poses(start, p0, problem, iterations=2, damping=damping)
    assert damping.mu[0] != 1e-3 and log1
    _, _, log2 = optimise_joints_and_poses(mid, p1, problem, iterations=2, damping=damping)
    assert log2 and log2[-1] <= log1[-1]


def test_gain_tol_stops_when_the_next_iteration_is_expected_to_gain_little():
    """With gain_tol the iterations are a prefix of those without it, ending at the first iteration after
    which the expected decrease d₂²/d₁ falls below gain_tol · E."""
    model, poses, scans = hybrid_truth(8)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start, p0 = _perturbed(model, poses)
    problem = JointPoseProblem(obj)
    q0 = problem.value(start, p0)
    _, _, full = optimise_joints_and_poses(start, p0, problem, iterations=8, damping=GainRatioDamping())
    seq = [q0] + full
    expected = [(seq[i - 1] - seq[i]) ** 2 / (seq[i - 2] - seq[i - 1]) / seq[i]
                for i in range(2, len(seq))]                 # after i iterations: expected next gain / E
    tol = float(np.median(expected))
    stop = next(i for i, e in enumerate(expected) if e < tol) + 2        # iterations run
    _, _, early = optimise_joints_and_poses(start, p0, problem, iterations=8, damping=GainRatioDamping(), gain_tol=tol)
    assert 2 <= stop < len(full) and len(early) == stop
    assert np.allclose(early, full[:stop], rtol=1e-12, atol=0)
