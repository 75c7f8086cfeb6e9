"""Joints and per-scan poses by Levenberg–Marquardt with a Schur complement (spec §3.4 (C)).

Parameters (all increments, applied by :func:`apply_increment`):

* shared block, per non-root bone b: the joint centre ``δh_b`` (3, metres) and the twist-axis direction
  ``δo_b`` (2, radians: a rotation of the frame about its local X and Z axes; the roll about Y is a
  gauge freedom of the swing/twist split and is not a parameter).  Changing the frame keeps every scan's
  *world* joint rotation (the local quaternion is re-expressed), so δo only moves the swing/twist split;
* per-scan block, scan m: bone-local rotation increments ``q_b ← q_b · exp(δr_b)`` for every bone (3 each,
  full-angle rotation vectors, bone 0 = global rotation) and the root translation ``δt`` (3, metres).
  The root head and frame are gauge (they only re-parameterise the global motion) and stay fixed.

Residuals: data ``p − s`` and ``√α (L p − L s)`` of every scan, and the left/right bone-length symmetry
residuals ``√λ (‖h_suc(l) − h_l‖ − ‖h_suc(r) − h_r‖)`` (spec Eq. 3.23 with the recommended
length-difference form).  The Jacobian has the arrow-head structure ``[S_m | O_m]`` per scan; the normal
equations are reduced to the shared block by the Schur complement
``(H_ss − Σ_m H_so,m H_oo,m⁻¹ H_os,m) δs = −g_s + Σ_m H_so,m H_oo,m⁻¹ g_o,m`` and back-substituted.
Damping: Levenberg–Marquardt ``μ (diag H_data + ε)`` (the diagonal of the data part: the symmetry
weight λ ≈ 1e10 would otherwise freeze the joints it couples); a step is accepted only if the objective
decreases.

Jacobian of the posed vertices: analytic, from :mod:`solver.jacobians` (:func:`posed_jacobians`);
:func:`posed_jacobians_fd` computes the same by central differences through :func:`apply_increment`
(the tests compare them).
"""
import copy

import numpy as np

from .errors import Cancelled  # noqa: F401  (raised by progress callbacks)
from .model import Poses, Skeleton
from .rotations import matrix_to_quat, quat_conj, quat_mul, quat_normalize, rotvec_to_matrix, rotvec_to_quat
from .jacobians import frame_jacobian, joint_jacobian, pose_jacobian
from .skinning import AnchorGroups, hybrid_skin

FD_STEP = 1e-6


def sizes(num_bones):
    """``(n_shared, n_own)`` parameter counts."""
    return 5 * (num_bones - 1), 3 * num_bones + 3


def apply_increment(skeleton, poses, d_shared, d_own):
    """New ``(skeleton, poses)`` after the increments ``d_shared (5(B−1),)`` and ``d_own (M, 3B+3)``."""
    B, M = skeleton.num_bones, len(poses)
    ds = np.asarray(d_shared, dtype=np.float64).reshape(B - 1, 5)
    do = np.asarray(d_own, dtype=np.float64).reshape(M, 3 * B + 3)
    q = quat_mul(poses.rotations, rotvec_to_quat(do[:, :3 * B].reshape(M, B, 3)))
    F = skeleton.frames.copy()
    heads = skeleton.heads.copy()
    heads[1:] += ds[:, :3]
    omega = ds[:, 3:4] * F[1:, :, 0] + ds[:, 4:5] * F[1:, :, 2]          # world axis-angle (B-1, 3)
    F_new = F.copy()
    F_new[1:] = rotvec_to_matrix(omega) @ F[1:]
    g = matrix_to_quat(np.swapaxes(F_new, -1, -2) @ F)                   # local re-expression F'ᵀF
    q = quat_normalize(quat_mul(quat_mul(g[None], q), quat_conj(g)[None]))
    length = np.linalg.norm(skeleton.tails - skeleton.heads, axis=1)
    sk = Skeleton(list(skeleton.names), skeleton.parents.copy(), heads,
                  heads + length[:, None] * F_new[:, :, 1], F_new)
    return sk, Poses(q, poses.translations + do[:, 3 * B:], poses.scales.copy())


def _with(model, skeleton):
    m = copy.copy(model)
    m.skeleton = skeleton
    return m


def posed_jacobians(model, poses, own_only=False):
    """Analytic Jacobians of the posed vertices ``(J_shared (M,3V,n_s), J_own (M,3V,n_o))`` in this
    module's layout, from :mod:`solver.jacobians` (pose, joint-centre and frame Jacobians; the frame
    columns are its world-ω columns projected on the frame's X and Z axes).  own_only: poses only,
    ``J_shared`` has no columns (joint and frame Jacobians are not computed)."""
    sk, M, V, B = model.skeleton, len(poses), model.num_vertices, model.skeleton.num_bones
    groups = AnchorGroups(model)
    _, Jp = pose_jacobian(model, poses, groups)                          # (M,V,3,4+3B): t, s, δ_b
    if own_only:
        Jo = np.concatenate([Jp[..., 4:], Jp[..., :3]], axis=3).reshape(M, 3 * V, 3 * B + 3)
        return np.zeros((M, 3 * V, 0)), Jo
    _, Jh = joint_jacobian(model, poses, groups)                         # (M,V,3,3B)
    _, Jf = frame_jacobian(model, poses, groups)                         # (M,V,3,3B) world ω_b
    Jo = np.concatenate([Jp[..., 4:], Jp[..., :3]], axis=3).reshape(M, 3 * V, 3 * B + 3)
    Jf = Jf.reshape(M, V, 3, B, 3)
    Jx = np.einsum("mvibk,bk->mvib", Jf, sk.frames[:, :, 0])
    Jz = np.einsum("mvibk,bk->mvib", Jf, sk.frames[:, :, 2])
    Js = np.concatenate([Jh.reshape(M, V, 3, B, 3), Jx[..., None], Jz[..., None]], axis=4)[:, :, :, 1:]
    return Js.reshape(M, 3 * V, 5 * (B - 1)), Jo


def posed_jacobians_fd(model, poses, step=FD_STEP):
    """The same Jacobians by central differences through :func:`apply_increment` (reference for tests)."""
    sk, M, V = model.skeleton, len(poses), model.num_vertices
    n_s, n_o = sizes(sk.num_bones)
    Js = np.empty((M, 3 * V, n_s))
    Jo = np.empty((M, 3 * V, n_o))
    zs, zo = np.zeros(n_s), np.zeros((M, n_o))
    for j in range(n_s):
        e = zs.copy()
        e[j] = step
        sp_, pp = apply_increment(sk, poses, e, zo)
        sm_, pm = apply_increment(sk, poses, -e, zo)
        diff = hybrid_skin(_with(model, sp_), pp) - hybrid_skin(_with(model, sm_), pm)
        Js[:, :, j] = diff.reshape(M, -1) / (2 * step)
    for j in range(n_o):
        e = zo.copy()
        e[:, j] = step
        _, pp = apply_increment(sk, poses, zs, e)
        _, pm = apply_increment(sk, poses, zs, -e)
        Jo[:, :, j] = (hybrid_skin(model, pp) - hybrid_skin(model, pm)).reshape(M, -1) / (2 * step)
    return Js, Jo


def symmetry_residuals(skeleton, sym_pairs):
    """Bone-length differences ``(P,)`` (metres) and their Jacobian ``(P, n_s)`` w.r.t. the shared block.
    sym_pairs: ``[(l, suc_l, r, suc_r), ...]`` bone indices (the bone of l runs from head l to head suc_l)."""
    h = skeleton.heads
    n_s, _ = sizes(skeleton.num_bones)
    r = np.zeros(len(sym_pairs))
    J = np.zeros((len(sym_pairs), n_s))
    for i, (l, sl, rr, sr) in enumerate(sym_pairs):
        bl, br = h[sl] - h[l], h[sr] - h[rr]
        nl, nr = np.linalg.norm(bl), np.linalg.norm(br)
        r[i] = nl - nr
        for bone, sign, u in ((sl, 1, bl / nl), (l, -1, bl / nl), (sr, -1, br / nr), (rr, 1, br / nr)):
            if bone > 0:
                J[i, 5 * (bone - 1):5 * (bone - 1) + 3] += sign * u
    return r, J


def normal_blocks(Js, Jo, rd, rl, L, alpha):
    """Gauss–Newton blocks from posed-vertex Jacobians and residuals.

    Js (M,3V,n_s), Jo (M,3V,n_o); rd, rl (M,V,3) data and Laplacian residuals; L (V,V).
    Returns ``H_ss (n_s,n_s), H_so (M,n_s,n_o), H_oo (M,n_o,n_o), g_s (n_s,), g_o (M,n_o)``."""
    M, R3, n_s = Js.shape
    V = R3 // 3
    n_o = Jo.shape[2]

    def lap(J):
        n = J.shape[2]
        return (L @ J.reshape(M, V, 3 * n).transpose(1, 0, 2).reshape(V, -1)).reshape(V, M, 3, n) \
            .transpose(1, 0, 2, 3).reshape(M, R3, n)

    LJs, LJo = lap(Js), lap(Jo)
    rd, rl = rd.reshape(M, -1), rl.reshape(M, -1)
    # einsum, not BLAS matmul: on the shared 2-core machine a multi-threaded BLAS was measured 4-5x slower
    # (one LM iteration, 13,380 v x 10 scans: 9.4-10.1 s CPU with einsum, 38-53 s with matmul)
    H_ss = np.einsum("mri,mrj->ij", Js, Js) + alpha * np.einsum("mri,mrj->ij", LJs, LJs)
    H_so = np.einsum("mri,mrj->mij", Js, Jo) + alpha * np.einsum("mri,mrj->mij", LJs, LJo)
    H_oo = np.einsum("mri,mrj->mij", Jo, Jo) + alpha * np.einsum("mri,mrj->mij", LJo, LJo)
    g_s = np.einsum("mri,mr->i", Js, rd) + alpha * np.einsum("mri,mr->i", LJs, rl)
    g_o = np.einsum("mri,mr->mi", Jo, rd) + alpha * np.einsum("mri,mr->mi", LJo, rl)
    return H_ss, H_so, H_oo, g_s, g_o


def schur_solve(H_ss, H_so, H_oo, g_s, g_o):
    """Solve the arrow-head system ``[[H_ss, H_so_1.., ], [H_so_mᵀ, H_oo_m]] [x_s; x_m] = [g_s; g_o_m]``
    by eliminating the per-scan blocks.  Returns ``(x_s (n_s,), x_o (M,n_o))``."""
    Y = np.linalg.solve(H_oo, np.concatenate([np.swapaxes(H_so, 1, 2), g_o[:, :, None]], axis=2))
    HinvHos, Hinv_go = Y[:, :, :-1], Y[:, :, -1]
    S = H_ss - np.einsum("mij,mjk->ik", H_so, HinvHos)
    rhs = g_s - np.einsum("mij,mj->i", H_so, Hinv_go)
    x_s = np.linalg.solve(S, rhs)
    x_o = Hinv_go - np.einsum("mij,j->mi", HinvHos, x_s)
    return x_s, x_o


SCAN_CHUNK = 2      # scans whose Jacobians are held in memory at once


def gauss_newton_blocks(model, poses, objective, chunk=SCAN_CHUNK, own_only=False):
    """:func:`normal_blocks` accumulated over chunks of scans, so that only ``chunk`` scans' Jacobians
    are in memory at once.  Returns ``H_ss, H_so (M,..), H_oo (M,..), g_s, g_o (M,..)``; with own_only
    (poses only) the shared blocks have size 0."""
    M = len(poses)
    rd, rl = objective.residuals(hybrid_skin(model, poses))
    parts = []
    for m0 in range(0, M, chunk):
        sl = slice(m0, min(M, m0 + chunk))
        sub = Poses(poses.rotations[sl], poses.translations[sl], poses.scales[sl])
        Js, Jo = posed_jacobians(model, sub, own_only)
        parts.append(normal_blocks(Js, Jo, rd[sl], rl[sl], objective.L, objective.alpha))
    H_ss = sum(p[0] for p in parts)
    g_s = sum(p[3] for p in parts)
    return (H_ss, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]), g_s,
            np.concatenate([p[4] for p in parts]))


class JointPoseProblem:
    """Objective ``Q + λ Q_sym`` as a function of (skeleton, poses) for a fixed model skin and rest mesh."""

    def __init__(self, objective, sym_pairs=(), lam=1e10):
        self.objective = objective
        self.sym_pairs = list(sym_pairs)
        self.lam = float(lam)

    def value(self, model, poses):
        q = self.objective.value(hybrid_skin(model, poses))
        if self.sym_pairs and self.lam > 0:
            r, _ = symmetry_residuals(model.skeleton, self.sym_pairs)
            q += self.lam * float(r @ r)
        return q


def optimise_joints_and_poses(model, poses, problem, iterations=10, mu=1e-3, step_tol=1e-9, progress=None,
                              fix_joints=False):
    """Levenberg–Marquardt on joints (centres + twist axes) and all per-scan poses.

    model: current :class:`Model` (its skin and rest mesh are held fixed); poses: current poses;
    problem: :class:`JointPoseProblem`.  fix_joints: keep joint centres and axes (poses only).  Returns ``(model, poses, log)`` with log the objective after every
    accepted step (never increasing).  ``progress(fraction, stage, objective)`` after each iteration."""
    obj = problem.objective
    n_s, _ = sizes(model.skeleton.num_bones)
    E = problem.value(model, poses)
    log = []
    for it in range(iterations):
        H_ss, H_so, H_oo, g_s, g_o = gauss_newton_blocks(model, poses, obj, own_only=fix_joints)
        # damping from the data part only: the huge symmetry weight must not freeze the joints it couples
        diag_s = np.diag(H_ss).copy()
        if problem.sym_pairs and problem.lam > 0 and not fix_joints:
            r, J = symmetry_residuals(model.skeleton, problem.sym_pairs)
            H_ss = H_ss + problem.lam * J.T @ J
            g_s = g_s + problem.lam * J.T @ r
        scale_s = diag_s.mean() if diag_s.size else 1.0
        scale_o = np.diagonal(H_oo, axis1=1, axis2=2).mean()
        accepted = False
        for _ in range(12):
            Ds = mu * (diag_s + 1e-6 * scale_s)
            Do = mu * (np.diagonal(H_oo, axis1=1, axis2=2) + 1e-6 * scale_o)
            H_oo_d = H_oo + Do[:, :, None] * np.eye(H_oo.shape[1])
            if fix_joints:
                x_s, x_o = np.zeros(n_s), np.linalg.solve(H_oo_d, -g_o[..., None])[..., 0]
            else:
                x_s, x_o = schur_solve(H_ss + np.diag(Ds), H_so, H_oo_d, -g_s, -g_o)
            sk_new, poses_new = apply_increment(model.skeleton, poses, x_s, x_o)
            model_new = _with(model, sk_new)
            E_new = problem.value(model_new, poses_new)
            if E_new < E:
                accepted = True
                step = np.sqrt(x_s @ x_s + np.sum(x_o * x_o))
                model, poses, E = model_new, poses_new, E_new
                mu = max(mu / 3.0, 1e-9)
                break
            mu *= 4.0
        if progress is not None:
            progress((it + 1) / iterations, "joints and poses (Gauss-Newton)", E)
        if not accepted:
            break
        log.append(E)
        if step < step_tol:
            break
    return model, poses, log
