"""Rest vertices by one sparse linear least-squares solve (dissertation (model-adaptive mocap) §3.4 (B)).

With weights, joints and poses fixed every posed vertex is affine in its rest position,
``p_m,v = A_m,v x_v + b_m,v`` (:func:`solver.rig.skinning.affine_form`).  Q is then quadratic in x:
``Σ_m ‖A_m x + b_m − s_m‖² + α ‖(L⊗I)(A_m x + b_m − s_m)‖²``.  Its minimiser solves the normal equations
``Σ_m A_mᵀ (I + α (LᵀL)⊗I) A_m x = Σ_m A_mᵀ (I + α (LᵀL)⊗I)(s_m − b_m)``, a sparse SPD system of size
3V.  With G = LᵀL (the two-ring pattern) its 3×3 block (v, w) is ``(δ_vw + α G_vw) C_vw`` with
``C_vw = Σ_m A_m,vᵀ A_m,w``: the C blocks of the upper triangle of G's pattern are computed at once
(batched 3×(3M) by (3M)×3 products), the lower ones are their transposes.  The system is solved by
sparse LU with a symmetric ordering and diagonal pivots (scipy's SuperLU, ``MMD_AT_PLUS_A``,
``SymmetricMode``; no CHOLMOD): SuperLU's default COLAMD column ordering fills several times more.

Repeated solves (:class:`ShapePreconditioner`, beyond the dissertation: learn_rig solves for the rest
vertices in every round with the same mesh and α): conjugate gradients on the same normal equations,
started from the current rest vertices and preconditioned by the factorisation of the scalar matrix
``I + α G`` (V×V, factored once) scaled per vertex by ``c_v = tr(C_vv) / 3``: where neighbouring
vertices move alike ``C_vw ≈ √(c_v c_w) I``, so the preconditioned spectrum is close to 1.  It stops at
a residual of ``CG_RTOL`` × the right-hand side (Q then differs from the direct solution's by
``rᵀN⁻¹r``, far below the objective's own rounding) and falls back to the direct solve if that is not
reached in ``CG_MAX_ITERATIONS``.  Many scans: the pair products are computed in cache-sized chunks
(:func:`_pair_products`).  docs/learn_rig_solver.md has the timings.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..rig.skinning import affine_form

CHUNK_BYTES = 2 ** 21   # bytes per gathered operand of one batched product (stays in cache)


def _pair_products(A, v, w):
    """``C (n,3,3)`` with ``C[k] = Σ_m A[m, v[k]]ᵀ A[m, w[k]]`` for A (M,V,3,3) and pairs v, w (n,).

    The pairs are processed in chunks of ``CHUNK_BYTES / (72 M)`` pairs (each gathered operand
    ``(chunk, 3M, 3)`` float64 ~2 MiB), so the gathers are written to cache-resident buffers: with a
    fixed chunk of pairs the gathers of many scans grow to hundreds of MB and run at memory speed."""
    M, V = A.shape[:2]
    stacked = np.ascontiguousarray(A.transpose(1, 0, 2, 3).reshape(V, 3 * M, 3))     # rows (m, j)
    stacked_t = np.ascontiguousarray(stacked.transpose(0, 2, 1))
    C = np.empty((len(v), 3, 3))
    chunk = max(16, CHUNK_BYTES // (3 * M * 3 * 8))
    for s in range(0, len(v), chunk):
        C[s:s + chunk] = np.matmul(np.take(stacked_t, v[s:s + chunk], axis=0),
                                   np.take(stacked, w[s:s + chunk], axis=0))
    return C


def _block_matrix(pattern, blocks, upper):
    """Sparse BSR ``(3V,3V)`` with the 3×3 blocks ``blocks (n,3,3)`` at the upper-triangle entries
    ``upper`` (COO, row <= col) of the symmetric CSR ``pattern`` (V,V), their transposes below."""
    V = pattern.shape[0]
    rows = np.repeat(np.arange(V), np.diff(pattern.indptr))
    cols = pattern.indices
    lo = np.minimum(rows, cols).astype(np.int64)
    hi = np.maximum(rows, cols).astype(np.int64)
    key = upper.row.astype(np.int64) * V + upper.col
    order = np.argsort(key)
    idx = order[np.searchsorted(key, lo * V + hi, sorter=order)]
    full = np.take(blocks, idx, axis=0)
    below = rows > cols
    full[below] = full[below].transpose(0, 2, 1)
    return sp.bsr_matrix((full, cols, pattern.indptr), shape=(3 * V, 3 * V))


def normal_equations(A, b, scans, L, alpha):
    """Normal matrix ``(3V,3V)`` (BSR, 3×3 blocks) and right-hand side ``(3V,)`` for affine maps A (M,V,3,3),
    b (M,V,3), scans (M,V,3), Laplacian L (V,V), α >= 0 (see the module docstring)."""
    M, V = A.shape[:2]
    eye = sp.identity(V, format="csr")
    L = sp.csr_matrix(L)
    S = (L.T @ L + eye).tocsr() if alpha > 0 else eye                # pattern incl. the diagonal
    S.sum_duplicates()
    S.sort_indices()
    upper = sp.triu(S).tocoo()
    diag = upper.row == upper.col
    coef = alpha * (upper.data - diag) + diag                         # δ_vw + α G_vw
    blocks = coef[:, None, None] * _pair_products(A, upper.row, upper.col)
    E = np.asarray(scans, dtype=np.float64) - b                                        # (M,V,3)
    if alpha > 0:
        GE = (S - eye) @ E.transpose(1, 0, 2).reshape(V, 3 * M)
        E = E + alpha * GE.reshape(V, M, 3).transpose(1, 0, 2)
    rhs = np.einsum("mvji,mvj->vi", A, E).ravel()
    return _block_matrix(S, blocks, upper), rhs


def _solve_spd(N, rhs):
    """Solution of the SPD system ``N x = rhs`` by SuperLU with a symmetric minimum-degree ordering and
    diagonal pivots; SuperLU's default partial pivoting if that breaks down (non-finite result)."""
    N = N.tocsc()
    x = spla.splu(N, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options=dict(SymmetricMode=True)).solve(rhs)
    if not np.all(np.isfinite(x)):
        x = spla.splu(N, permc_spec="MMD_AT_PLUS_A").solve(rhs)
    return x


CG_RTOL = 1e-9           # ‖N x − rhs‖ / ‖rhs‖ at which conjugate gradients stop
CG_MAX_ITERATIONS = 200  # then the direct solve
CG_TICK_EVERY = 10       # conjugate-gradient iterations between progress calls
STAGE = "rest vertices (sparse least squares)"


class ShapePreconditioner:
    """The factorisation of ``I + α LᵀL`` (V×V) for :func:`solve_rest_vertices` with conjugate
    gradients; depends on the mesh's Laplacian ``L (V,V)`` and α only (see the module docstring)."""

    def __init__(self, L, alpha):
        L = sp.csr_matrix(L)
        K = (sp.identity(L.shape[0], format="csc") + float(alpha) * (L.T @ L)).tocsc()
        self.K_diag = K.diagonal()
        self.lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                            options=dict(SymmetricMode=True))

    def inverse(self, N):
        """``r ↦ P⁻¹ r`` for the normal matrix N ``(3V,3V)`` of this (L, α): the scalar factor applied
        per coordinate and scaled by ``1 / √c_v`` on both sides, ``c_v = tr(N_vv) / (3 (1 + α G_vv))``."""
        V = self.K_diag.shape[0]
        scale = 1.0 / np.sqrt(N.diagonal().reshape(V, 3).mean(axis=1) / self.K_diag)

        def apply(r):
            return (self.lu.solve(r.reshape(V, 3) * scale[:, None]) * scale[:, None]).ravel()
        return apply


def conjugate_gradients(N, rhs, x0, precondition, rtol=CG_RTOL, max_iterations=CG_MAX_ITERATIONS, tick=None):
    """Preconditioned conjugate gradients for SPD ``N (n,n)``: ``(x, converged)`` from ``x0 (n,)`` with
    ``precondition(r) ≈ N⁻¹ r``; converged when ``‖N x − rhs‖ ≤ rtol ‖rhs‖`` within max_iterations.
    tick(fraction of max_iterations): every ``CG_TICK_EVERY`` iterations (may raise to stop)."""
    x = np.array(x0, dtype=np.float64)
    r = rhs - N @ x
    goal = rtol * np.linalg.norm(rhs)
    z = precondition(r)
    d = z.copy()
    rz = r @ z
    for it in range(max_iterations):
        if np.linalg.norm(r) <= goal:
            return x, True
        if tick is not None and it and it % CG_TICK_EVERY == 0:
            tick(it / max_iterations)
        Nd = N @ d
        step = rz / (d @ Nd)
        x += step * d
        r -= step * Nd
        z = precondition(r)
        rz, rz_old = r @ z, rz
        d = z + (rz / rz_old) * d
    return x, bool(np.linalg.norm(r) <= goal)


def solve_rest_vertices(model, poses, scans, L, alpha, preconditioner=None, with_posed=False, progress=None):
    """The rest vertices ``(V,3)`` minimising Q with everything else fixed (metres): by the direct sparse
    solve, or with a :class:`ShapePreconditioner` for (L, α) by conjugate gradients from the model's
    current rest vertices (the direct solve if they do not converge).  with_posed: return
    ``(x, posed (M,V,3))``, the posed vertices ``A x + b`` of the affine form already at hand (equal to
    ``hybrid_skin`` of the model with rest vertices x up to rounding, at a tenth of its cost).
    progress(fraction, stage, None): after the affine form, the normal equations, every
    ``CG_TICK_EVERY`` CG iterations and before a direct solve; may raise ``Cancelled`` (nothing is
    changed: the model is only read)."""
    say = (lambda f, stage=STAGE: None) if progress is None else (lambda f, stage=STAGE: progress(f, stage, None))
    A, b = affine_form(model, poses)
    say(0.1)
    N, rhs = normal_equations(A, b, np.asarray(scans, dtype=np.float64), L, alpha)
    say(0.3)
    ok = False
    if preconditioner is not None:
        x, ok = conjugate_gradients(N, rhs, model.rest_vertices.ravel(), preconditioner.inverse(N), CG_RTOL,
                                    CG_MAX_ITERATIONS, lambda f: say(0.3 + 0.6 * f))
    if not ok:
        say(0.9, "rest vertices (direct sparse solve)")
    x = (x if ok else _solve_spd(N, rhs)).reshape(-1, 3)
    if not with_posed:
        return x
    return x, np.einsum("mvij,vj->mvi", A, x) + b
