"""Joints and per-scan poses by Levenberg–Marquardt with a Schur complement (dissertation
(model-adaptive mocap) §3.4 (C); step (a) of the rig learner, docs/learn_rig_solver.md).

Parameters (all increments, applied by :func:`apply_increment`):

* shared block, per non-root bone b: the joint centre ``δh_b`` (3, metres) and the twist-axis direction
  ``δo_b`` (2, radians: a rotation of the frame about its local X and Z axes; the roll about Y is a
  gauge freedom of the swing/twist split and is not a parameter).  Changing the frame keeps every scan's
  *world* joint rotation (the local quaternion is re-expressed), so δo only moves the swing/twist split;
* per-scan block, scan m: bone-local rotation increments ``q_b ← q_b · exp(δr_b)`` for every bone (3 each,
  full-angle rotation vectors, bone 0 = global rotation) and the root translation ``δt`` (3, metres).
  The root head and frame are gauge (they only re-parameterise the global motion) and stay fixed.

Residuals: data ``p − s`` and ``√α (L p − L s)`` of every scan, and the left/right bone-length symmetry
residuals ``√λ (‖h_suc(l) − h_l‖ − ‖h_suc(r) − h_r‖)`` (dissertation (model-adaptive mocap) Eq. 3.23 in
the length-difference form), and an optional weak joint prior ``√κ (h_b − h⁰_b)`` (not in the
dissertation, off by default, see :class:`JointPoseProblem`).  The Jacobian has the arrow-head structure
``[S_m | O_m]`` per scan; the normal equations are reduced to the shared block by the Schur complement
``(H_ss − Σ_m H_so,m H_oo,m⁻¹ H_os,m) δs = −g_s + Σ_m H_so,m H_oo,m⁻¹ g_o,m`` and back-substituted.
The iterations are those of :func:`solver.fit.least_squares.levenberg_marquardt` with the gain-ratio
damping rule, damping ``μ (diag H_data + ε)`` (the diagonal of the data part: the symmetry weight
λ ≈ 1e10 would otherwise freeze the joints it couples); a step is accepted only if the objective decreases.

Jacobian of the posed vertices: analytic, from :mod:`solver.rig.jacobians`.  The solver never forms it
densely: a vertex depends only on its anchor's chain and children, so each anchor group's Jacobian is
``R T`` (per-vertex columns R, per-scan combination T, :func:`jacobians.group_jacobian`) and the
normal-equation blocks are assembled from the small Gram matrices of R (:func:`normal_equation_blocks`,
BLAS on one thread).  :func:`posed_jacobians` gives the dense Jacobian, :func:`posed_jacobians_fd` the
same by central differences through :func:`apply_increment`, :func:`dense_normal_blocks` the blocks from
dense Jacobians (the tests compare them).
"""
import copy

import numpy as np
import scipy.sparse as sp

from .. import parallel
from ..errors import Cancelled  # noqa: F401  (raised by progress callbacks)
from ..rig.model import Poses, Skeleton
from ..geometry.rotations import matrix_to_quat, quat_conj, quat_mul, quat_normalize, rotvec_to_matrix, rotvec_to_quat
from ..fit.least_squares import GainRatioDamping, Limits, levenberg_marquardt
from ..parallel import single_blas_thread
from ..rig.jacobians import _chain_of, dense_jacobian, expand_gram, gram, group_jacobian, jacobian_terms
from ..rig.skinning import AnchorGroups, hybrid_skin

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


def _columns(num_bones, own_only):
    """Columns of the pieces of :func:`jacobians.group_jacobian` in this module's layout ``[shared | own]``
    and the number of shared columns (0 with own_only)."""
    B = num_bones
    n_s = 0 if own_only else 5 * (B - 1)
    cols = {("rot", b): n_s + 3 * b for b in range(B)}
    cols["t"] = n_s + 3 * B
    if not own_only:
        for b in range(1, B):
            cols[("head", b)], cols[("frame", b)] = 5 * (b - 1), 5 * (b - 1) + 3
    return cols, n_s


def _frame_basis(model, own_only):
    """Frame rotation axes ``(B, 3, 2)`` of the shared block: each frame's X and Z axes (None: poses only)."""
    return None if own_only else model.skeleton.frames[:, :, [0, 2]]


def posed_jacobians(model, poses, own_only=False):
    """Analytic Jacobians of the posed vertices ``(J_shared (M,3V,n_s), J_own (M,3V,n_o))`` in this
    module's layout, from :mod:`solver.rig.jacobians` (pose, joint-centre and frame Jacobians; the frame
    columns are rotations about the frame's X and Z axes).  own_only: poses only, ``J_shared`` has no
    columns.  Dense (for tests; the solver uses the compact blocks of :func:`normal_equation_blocks`)."""
    M, V = len(poses), model.num_vertices
    cols, n_s = _columns(model.skeleton.num_bones, own_only)
    n = n_s + sizes(model.skeleton.num_bones)[1]
    _, J = dense_jacobian(model, poses, cols, n, heads=not own_only, frame_basis=_frame_basis(model, own_only))
    J = J.reshape(M, 3 * V, n)
    return J[..., :n_s].copy(), J[..., n_s:].copy()


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


def dense_normal_blocks(Js, Jo, rd, rl, L, alpha):
    """Normal-equation blocks from dense posed-vertex Jacobians and residuals (reference for tests).

    Js (M,3V,n_s), Jo (M,3V,n_o); rd, rl (M,V,3) data and Laplacian residuals; L (V,V).
    Returns ``H_ss (n_s,n_s), H_so (M,n_s,n_o), H_oo (M,n_o,n_o), g_s (n_s,), g_o (M,n_o)``."""
    M, R3, n_s = Js.shape
    V = R3 // 3
    J = np.concatenate([Js, Jo], axis=2)
    n = J.shape[2]
    LJ = (L @ J.reshape(M, V, 3 * n).transpose(1, 0, 2).reshape(V, -1)).reshape(V, M, 3, n) \
        .transpose(1, 0, 2, 3).reshape(M, R3, n)
    A = np.concatenate([J, rd.reshape(M, R3, 1)], axis=2)
    B = np.concatenate([LJ, rl.reshape(M, R3, 1)], axis=2)
    H = np.matmul(np.swapaxes(A, 1, 2), A) + alpha * np.matmul(np.swapaxes(B, 1, 2), B)
    return (H[:, :n_s, :n_s].sum(axis=0), H[:, :n_s, n_s:n], H[:, n_s:n, n_s:n], H[:, :n_s, n].sum(axis=0),
            H[:, n_s:n, n])


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


def _local_columns(skeleton, a, kids, cols, n):
    """Compact columns of anchor group a (the pieces that move its vertices): ``(local, index)`` with
    ``local`` the first column of every piece in the group's block and ``index (C+1,)`` the global column
    of every block column plus the residual column n."""
    chain = _chain_of(skeleton, a)
    keys = [("rot", b) for b in chain] + ["t"] + [("head", b) for b in chain] + \
        [(kind, c) for c in kids for kind in ("rot", "frame", "head")]
    local, index = {}, []
    for key in (k for k in keys if k in cols):
        local[key] = len(index)
        index.extend(range(cols[key], cols[key] + (2 if key[0] == "frame" else 3)))
    return local, np.array(index + [n])


class _Structure:
    """Sparsity structure of the normal equations (fixed while anchors, mesh and objective are).

    Every anchor group's Jacobian rows are non-zero only in its compact columns (:func:`_local_columns`);
    the Laplacian rows of a vertex whose one-ring lies in its group ("interior") too; the other
    ("boundary") rows of group a use the union of the columns of the groups they touch.  Vertices are in
    :class:`AnchorGroups` order; ``L`` = √α L permuted to it, ``scans`` and ``scan_lap`` (= √α L s) too."""

    def __init__(self, model, objective, own_only, laplacian_blocks=True):
        self.groups = groups = AnchorGroups(model)
        sk, order = model.skeleton, groups.order
        cols, self.n_s = _columns(sk.num_bones, own_only)
        self.n = self.n_s + sizes(sk.num_bones)[1]                   # also the residual column
        self.local, self.index = zip(*[_local_columns(sk, g[0], g[1], cols, self.n) for g in groups.groups])
        root_alpha = np.sqrt(objective.alpha)
        self.L = (root_alpha * objective.L).tocsr()[order][:, order].tocsr()
        self.scans = objective.scans[:, order]
        self.scan_lap = root_alpha * objective.scan_lap[:, order]
        weights = getattr(objective, "data_weights", None)      # a vertex subset's (solver.learn.coarse)
        self.sw = None if weights is None else np.sqrt(weights)[order]
        # the data rows are scaled by √w in place, so the Laplacian products take L diag(1/√w)
        L_cols = self.L if self.sw is None else (self.L @ sp.diags(1.0 / self.sw)).tocsr()
        bounds = np.array([g[2] for g in groups.groups] + [groups.num_vertices])
        self.interior, self.boundary = [], []
        for start, stop in zip(bounds[:-1], bounds[1:]) if laplacian_blocks else ():
            rows = L_cols[start:stop]
            outside = (rows.indices < start) | (rows.indices >= stop)
            nnz_row = np.repeat(np.arange(stop - start), np.diff(rows.indptr))
            touches = np.bincount(nnz_row[outside], minlength=stop - start) > 0
            empty = np.diff(rows.indptr) == 0                   # a subset's non-seed rows
            inner, edge = np.flatnonzero(~touches & ~empty), np.flatnonzero(touches)
            self.interior.append((rows[inner][:, start:stop], start + inner))
            if len(edge):
                self.boundary.append(self._boundary(rows[edge], start + edge, bounds))

    def _boundary(self, rows, vertices, bounds):
        """``(columns (U+1,), vertices, sources)``: boundary rows ``rows`` (csr) of one group, the global
        columns they touch (+ residual) and per touched group b ``(b, near, L_near, positions)``: its
        vertices that the rows touch (indices in b), √α L rows × those vertices (csr) and the positions
        of b's columns in U."""
        touched = np.unique(np.searchsorted(bounds, rows.indices, side="right") - 1)
        U = np.unique(np.concatenate([self.index[b][:-1] for b in touched]))
        sources = []
        for b in touched:
            L_b = rows[:, bounds[b]:bounds[b + 1]]
            near = np.unique(L_b.indices)
            sources.append((b, near, L_b[:, near].tocsr(), np.searchsorted(U, self.index[b][:-1])))
        return np.append(U, self.n), vertices, sources


def _chunk_system(st, model, poses, sl, own_only):
    """Gram matrices ``(N, n+1, n+1)`` of ``[J | r]`` over the data and √α-weighted Laplacian rows of the
    scans ``sl`` (``poses``), in the layout ``[shared | own | residual]``: the normal-equation blocks
    and (last column) the gradients of one scan each.  Every group's Jacobian is ``R T``
    (:func:`jacobians.group_jacobian`); its Gram matrices are formed from R and expanded by T."""
    bt = jacobian_terms(model, poses, heads=not own_only, frame_basis=_frame_basis(model, own_only))
    groups = st.groups.groups
    N, V = len(poses), model.num_vertices
    posed = np.empty((N, V, 3))
    RT = []
    for group, local, index in zip(groups, st.local, st.index):
        xp, R, T = group_jacobian(bt, st.groups, group, local, len(index) - 1, extra=1)
        posed[:, group[2]:group[3]] = xp
        RT.append((R, T))
    rl = (st.L @ posed.transpose(1, 0, 2).reshape(V, -1)).reshape(V, N, 3).transpose(1, 0, 2) - st.scan_lap[sl]
    H = np.zeros((st.n + 1, st.n + 1, N))        # scans last: each scatter moves whole N-vectors
    for (R, T), group, index, (L_in, inner) in zip(RT, groups, st.index, st.interior):
        R[..., -1] = posed[:, group[2]:group[3]] - st.scans[sl, group[2]:group[3]]
        if st.sw is not None:                            # weighted data rows (L_in carries 1/√w)
            R *= st.sw[None, group[2]:group[3], None, None]
        G = gram(R)
        if len(inner):                                   # interior Laplacian rows of all N scans at once
            Vg, c = R.shape[1], R.shape[-1]
            P = (L_in @ R.transpose(1, 0, 2, 3).reshape(Vg, -1)).reshape(len(inner), N, 3, c)
            P = P.transpose(1, 0, 2, 3)
            P[..., -1] = rl[:, inner]
            G += gram(P)
        H[index[:, None], index] += expand_gram(G, T).transpose(1, 2, 0)
    for index, vertices, sources in st.boundary:
        H[index[:, None], index] += _boundary_gram(RT, sources, rl[:, vertices], len(index)).transpose(1, 2, 0)
    return H.transpose(2, 0, 1)


def _boundary_gram(RT, sources, rl, width):
    """Gram matrices ``(N, width, width)`` of one group's boundary Laplacian rows: ``Σ_b √α L_b R_b T_b``
    in the union columns, the residual rl ``(N, n_B, 3)`` of the n_B rows (√α-weighted) last.  Built
    columns-first, ``Z (width, N, 3 n_B)``, so that each touched group adds whole rows."""
    N, nB = rl.shape[:2]
    Z = np.zeros((width, N, 3 * nB))
    for b, near, L_near, pos in sources:
        R, T = RT[b]
        r = T.shape[1]
        X = R[:, near, :, :-1].transpose(1, 0, 2, 3).reshape(len(near), -1)     # (k, N 3 r)
        LX = (L_near @ X).reshape(nB, N, 3 * r).transpose(1, 0, 2).reshape(N, 3 * nB, r)
        Z[pos] += np.matmul(np.swapaxes(T, 1, 2), np.swapaxes(LX, 1, 2)).transpose(1, 0, 2)
    Z[-1] = rl.reshape(N, -1)
    Z = Z.transpose(1, 0, 2)
    return np.matmul(Z, np.swapaxes(Z, 1, 2))


CHUNK_VERTEX_SCANS = 54000   # vertex-scans whose compact Jacobians are held at once: 4 scans of 13,380 v;
                             # small meshes take many scans per chunk


def scan_chunk(num_vertices):
    """Scans per chunk of :func:`normal_equation_blocks` for meshes of ``num_vertices`` vertices (≥ 1)."""
    return max(1, CHUNK_VERTEX_SCANS // max(int(num_vertices), 1))


def normal_equation_blocks(model, poses, objective, chunk=None, own_only=False, structure=None):
    """Normal-equation blocks (those of :func:`dense_normal_blocks`) at ``(model, poses)`` for ``objective``,
    accumulated over chunks of scans (default :func:`scan_chunk`) from compact per-anchor-group Jacobians
    (:class:`_Structure`; pass ``structure`` to reuse one built for this model's anchors and weights), so
    that only ``chunk`` scans' blocks are in memory at once.  Returns ``H_ss, H_so (M,..), H_oo (M,..),
    g_s, g_o (M,..)``; with own_only (poses only) the shared blocks have size 0."""
    st = _Structure(model, objective, own_only) if structure is None else structure
    M = len(poses)
    if chunk is None:                                   # at least one chunk per thread
        chunk = parallel.piece_size(M, scan_chunk(model.num_vertices))
    chunk = int(chunk)
    H = np.empty((M, st.n + 1, st.n + 1))

    def system(m0):
        sl = slice(m0, min(M, m0 + chunk))
        sub = Poses(poses.rotations[sl], poses.translations[sl], poses.scales[sl])
        return _chunk_system(st, model, sub, sl, own_only)

    starts = range(0, M, chunk)
    with single_blas_thread():              # chunks: half in a forked helper, or on the solver's threads
        for m0, block in zip(starts, parallel.fork_map(system, starts)):
            H[m0:m0 + chunk] = block
    n_s, n = st.n_s, st.n
    return (H[:, :n_s, :n_s].sum(axis=0), H[:, :n_s, n_s:n].copy(), H[:, n_s:n, n_s:n].copy(),
            H[:, :n_s, n].sum(axis=0), H[:, n_s:n, n].copy())


def gradient_blocks(model, poses, objective, own_only=False):
    """The gradient halves ``(g_s (n_s,), g_o (M, n_o))`` of :func:`normal_equation_blocks` (``Jᵀr`` over
    the data and Laplacian rows, m²) without the Gram matrices: ``g = Σ_v J_vᵀ e_v`` with one residual per
    vertex ``e = w (p − s) + α Lᵀ (L p − L s)``, per anchor group ``Tᵀ (Rᵀ e)``; about half the work of
    the blocks (no products of Jacobian columns)."""
    st = _Structure(model, objective, own_only, laplacian_blocks=False)
    M, V = len(poses), model.num_vertices
    posed = hybrid_skin(model, poses, st.groups)[:, st.groups.order]
    rl = (st.L @ posed.transpose(1, 0, 2).reshape(V, -1)).reshape(V, M, 3).transpose(1, 0, 2) - st.scan_lap
    e = posed - st.scans
    if st.sw is not None:
        e *= (st.sw ** 2)[None, :, None]
    e += (st.L.T @ rl.transpose(1, 0, 2).reshape(V, -1)).reshape(V, M, 3).transpose(1, 0, 2)
    g = np.zeros((M, st.n))
    chunk = scan_chunk(V)
    for m0 in range(0, M, chunk):
        sl = slice(m0, min(M, m0 + chunk))
        sub = Poses(poses.rotations[sl], poses.translations[sl], poses.scales[sl])
        bt = jacobian_terms(model, sub, heads=not own_only, frame_basis=_frame_basis(model, own_only))
        for group, local, index in zip(st.groups.groups, st.local, st.index):
            _, R, T = group_jacobian(bt, st.groups, group, local, len(index) - 1)
            gR = np.einsum("nvic,nvi->nc", R, e[sl, group[2]:group[3]])
            g[sl, index[:-1]] += np.einsum("nrc,nr->nc", T, gR)
    return g[:, :st.n_s].sum(axis=0), g[:, st.n_s:]


class JointPoseProblem:
    """Objective ``Q + λ Q_sym + κ Q_prior`` as a function of (skeleton, poses) for a fixed model skin and
    rest mesh.  ``Q_sym`` = Σ squared left/right bone-length differences (m², :func:`symmetry_residuals`);
    ``κ Q_prior = Σ_b≥1 κ_b ‖h_b − h⁰_b‖²`` (m²) ties the joint centres weakly to ``prior_heads (B,3)``
    (the initial rotation-centre estimates): near-hinge joints are poorly determined along their axis, and the
    data and Laplacian terms let them slide there.  kappa: κ_b, a scalar or ``(B−1,)`` per non-root joint,
    dimensionless (one joint displacement costs as much as κ_b vertex-scan residuals of the same length);
    :func:`relative_joint_prior` scales it to the data's curvature."""

    def __init__(self, objective, sym_pairs=(), lam=1e10, prior_heads=None, kappa=0.0):
        self.objective = objective
        self.sym_pairs = list(sym_pairs)
        self.lam = float(lam)
        self.prior_heads = None if prior_heads is None else np.asarray(prior_heads, dtype=np.float64)
        self.kappa = (np.zeros(0) if prior_heads is None else
                      np.broadcast_to(np.asarray(kappa, dtype=np.float64), (len(self.prior_heads) - 1,)).copy())

    def shared_value(self, skeleton):
        """``λ Q_sym + κ Q_prior`` (m²): the terms that depend on the skeleton only."""
        q = 0.0
        if self.sym_pairs and self.lam > 0:
            r, _ = symmetry_residuals(skeleton, self.sym_pairs)
            q += self.lam * float(r @ r)
        if np.any(self.kappa > 0):
            d = skeleton.heads[1:] - self.prior_heads[1:]
            q += float(self.kappa @ np.sum(d * d, axis=1))
        return q

    def add_shared_terms(self, skeleton, H_ss, g_s):
        """Gauss–Newton ``(H_ss, g_s)`` of the shared block with the symmetry and prior terms added."""
        H_ss, g_s = H_ss.copy(), g_s.copy()
        if self.sym_pairs and self.lam > 0:
            r, J = symmetry_residuals(skeleton, self.sym_pairs)
            H_ss += self.lam * J.T @ J
            g_s += self.lam * J.T @ r
        if np.any(self.kappa > 0):
            heads = (5 * np.arange(skeleton.num_bones - 1)[:, None] + np.arange(3)).ravel()
            H_ss[heads, heads] += np.repeat(self.kappa, 3)
            g_s[heads] += (self.kappa[:, None] * (skeleton.heads[1:] - self.prior_heads[1:])).ravel()
        return H_ss, g_s

    def value(self, model, poses, groups=None):
        """``Q + λ Q_sym + κ Q_prior`` (m²); groups: optional :class:`AnchorGroups` of the model."""
        return self.objective.value(hybrid_skin(model, poses, groups)) + self.shared_value(model.skeleton)


def relative_joint_prior(model, poses, objective, rho):
    """Per-joint prior weights ``κ_b = ρ · tr(H_hh,b) / 3`` ``(B−1,)``: ρ times the mean Gauss–Newton
    curvature of Q in joint b's centre at ``(model, poses)``.  Directions the data determine (curvature
    ~ tr/3) feel the prior as a ρ-fraction; a near-hinge joint's axis direction (curvature ≈ 0) is held
    by it.  Scale-free: the same ρ suits any scan count, vertex count and unit."""
    B = model.skeleton.num_bones
    H_ss = normal_equation_blocks(model, poses, objective)[0]
    heads = 5 * np.arange(B - 1)[:, None] + np.arange(3)
    return rho * np.diag(H_ss)[heads].sum(axis=1) / 3.0


class _JointPoseLeastSquares:
    """The joints-and-poses step as one problem of :func:`solver.fit.least_squares.levenberg_marquardt`:
    normal-equation blocks (:func:`normal_equation_blocks` plus the problem's shared terms), damping
    ``μ (diag H_data + 10⁻⁶ mean diag H_data)`` per block from the data part only (the symmetry weight
    λ ≈ 1e10 would otherwise freeze the joints it couples), steps by the Schur complement
    (:func:`schur_solve`; per scan with fix_joints).  ``log``: E after every accepted step.
    correction ``(c_s, c_o)``: a linear term ``2 cᵀ δ`` added to E, δ the sum of the accepted steps (the
    coarse-grid correction of :func:`optimise_joints_and_poses`)."""
    size = 1

    def __init__(self, model, poses, problem, fix_joints, value, correction=None):
        self.model, self.poses, self.problem, self.fix_joints = model, poses, problem, fix_joints
        self.structure = _Structure(model, problem.objective, fix_joints)      # anchors and weights stay fixed
        self.value = value
        self.log = []
        self.correction = correction
        self.moved = None if correction is None else (np.zeros_like(correction[0]), np.zeros_like(correction[1]))

    def _linear(self, steps):
        """``2 cᵀ (moved + steps)`` (0 without a correction)."""
        if self.correction is None:
            return 0.0
        (c_s, c_o), (m_s, m_o) = self.correction, self.moved
        return 2.0 * (float(c_s @ (m_s + steps[0][:len(c_s)])) + float(np.sum(c_o * (m_o + steps[1]))))

    def energy(self, idx):
        if self.value is None:
            self.value = self.problem.value(self.model, self.poses, self.structure.groups)
        return np.array([self.value], dtype=np.float64)

    def build(self, idx):
        H_ss, self.H_so, self.H_oo, g_s, self.g_o = normal_equation_blocks(
            self.model, self.poses, self.problem.objective, own_only=self.fix_joints, structure=self.structure)
        if self.correction is not None:
            g_s, self.g_o = g_s + self.correction[0], self.g_o + self.correction[1]
        self.diag_s = np.diag(H_ss).copy()
        if not self.fix_joints:
            H_ss, g_s = self.problem.add_shared_terms(self.model.skeleton, H_ss, g_s)
        self.H_ss, self.g_s = H_ss, g_s
        self.scale_s = self.diag_s.mean() if self.diag_s.size else 1.0
        self.scale_o = np.diagonal(self.H_oo, axis1=1, axis2=2).mean()
        return None

    def solve(self, idx, mu):
        mu = mu[0]
        Ds = mu * (self.diag_s + 1e-6 * self.scale_s)
        Do = mu * (np.diagonal(self.H_oo, axis1=1, axis2=2) + 1e-6 * self.scale_o)
        H_oo_d = self.H_oo + Do[:, :, None] * np.eye(self.H_oo.shape[1])
        if self.fix_joints:
            x_o = np.linalg.solve(H_oo_d, -self.g_o[..., None])[..., 0]
            return np.zeros(sizes(self.model.skeleton.num_bones)[0]), x_o
        return schur_solve(self.H_ss + np.diag(Ds), self.H_so, H_oo_d, -self.g_s, -self.g_o)

    def try_steps(self, idx, steps):
        skeleton, poses = apply_increment(self.model.skeleton, self.poses, *steps)
        self.trial = _with(self.model, skeleton), poses
        self.trial_steps = steps
        self.trial_value = self.problem.value(*self.trial, self.structure.groups) + self._linear(steps)
        return np.array([self.trial_value], dtype=np.float64)

    def accept(self, which):
        if which[0]:
            self.model, self.poses = self.trial
            self.log.append(self.trial_value)
            if self.correction is not None:
                m_s, m_o = self.moved
                self.moved = (m_s + self.trial_steps[0][:len(m_s)], m_o + self.trial_steps[1])

    def predicted_decrease(self, idx, steps):
        """Decrease of the Gauss–Newton model ``E + 2gᵀx + xᵀHx`` at the step (m²); the shared part is
        left out when its blocks are empty (poses only)."""
        x_s, x_o = steps
        xHx = np.einsum("mi,mij,mj->", x_o, self.H_oo, x_o)
        linear = np.sum(self.g_o * x_o)
        if len(self.g_s):
            xHx += x_s @ self.H_ss @ x_s + 2.0 * np.einsum("i,mij,mj->", x_s, self.H_so, x_o)
            linear += self.g_s @ x_s
        return np.array([-2.0 * linear - xHx])

    def step_norm(self, steps):
        x_s, x_o = steps
        return np.array([np.sqrt(x_s @ x_s + np.sum(x_o * x_o))])


def optimise_joints_and_poses(model, poses, problem, iterations=10, damping=None, step_tol=1e-9, progress=None,
                              fix_joints=False, value=None, gain_tol=0.0, correction=None):
    """Levenberg–Marquardt on joints (centres + twist axes) and all per-scan poses (module docstring).

    model: current :class:`Model` (its skin and rest mesh are held fixed); poses: current poses;
    problem: :class:`JointPoseProblem`.  fix_joints: keep joint centres and axes (poses only).
    iterations: normal-equation builds at most, each followed by up to 12 trial steps with rising damping.
    damping: a :class:`solver.fit.least_squares.GainRatioDamping` to start from (μ = 1e-3 if None), updated
    in place so that the next round continues from it.  value: the problem's value at (model, poses) if
    the caller knows it (else computed).  step_tol: stop after a step ``‖δ‖ ≤ step_tol``.  gain_tol (not in
    the dissertation): stop when the next iteration is expected to gain less than ``gain_tol · E``
    (:func:`solver.fit.least_squares.stalls`); 0: always run ``iterations``.
    ``progress(fraction, stage, objective)`` after each iteration.  correction ``(c_s (n_s,), c_o (M, n_o))``
    (on a vertex subset, :mod:`solver.learn.coarse`): minimise ``E + 2 cᵀ δ`` instead (δ: the steps taken),
    with c = the full problem's gradient minus this one's at the start, so that the first step follows
    the full gradient (the coarse-grid correction of multigrid's FAS); ``value`` then excludes the term.
    Returns ``(model, poses, log)`` with log the objective after every accepted step (never increasing).
    Runs with numpy's BLAS on one thread (:func:`solver.parallel.single_blas_thread`)."""
    damping = GainRatioDamping() if damping is None else damping
    lsq = _JointPoseLeastSquares(model, poses, problem, fix_joints, value, correction)
    limits = Limits(steps=iterations, rejections=12, step_tol=step_tol, gain_tol=gain_tol)
    report = None
    if progress is not None:
        def report(idx, used, energy):
            progress(used[0] / iterations, "joints and poses (Levenberg-Marquardt)", float(energy[0]))
    with single_blas_thread():
        levenberg_marquardt(lsq, damping, limits, report)
    return lsq.model, lsq.poses, lsq.log
