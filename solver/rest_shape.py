"""Rest vertices by one sparse linear least-squares solve (spec §3.4 (B)).

With weights, joints and poses fixed every posed vertex is affine in its rest position,
``p_m,v = A_m,v x_v + b_m,v`` (:func:`solver.skinning.affine_form`).  Q is then quadratic in x:
``Σ_m ‖A_m x + b_m − s_m‖² + α ‖(L⊗I)(A_m x + b_m − s_m)‖²``.  Its minimiser solves the normal equations
``Σ_m A_mᵀ (I + α (LᵀL)⊗I) A_m x = Σ_m A_mᵀ (I + α (LᵀL)⊗I)(s_m − b_m)``, a sparse SPD system of size
3V assembled as ``Σ_m A_mᵀA_m + α PᵀP`` with ``P`` the vertically stacked ``(L⊗I) A_m`` and solved
by sparse LU (scipy's SuperLU; no CHOLMOD).  Timed in bench/bench_learn_speed.py.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .skinning import affine_form


def _block_diag(A):
    """Block-diagonal sparse ``(3V,3V)`` of per-vertex 3×3 blocks ``A (V,3,3)``."""
    V = len(A)
    rows = (3 * np.arange(V)[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2)
    cols = (3 * np.arange(V)[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1)
    return sp.csr_matrix((A.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * V, 3 * V))


def _laplacian_times_blocks(L, A):
    """``(L⊗I) blockdiag(A)`` as sparse ``(3V,3V)``: block (v,n) = L[v,n] A[n]."""
    Lc = sp.coo_matrix(L)
    blocks = Lc.data[:, None, None] * A[Lc.col]                          # (nnz,3,3)
    i3 = np.arange(3)
    rows = 3 * Lc.row[:, None, None] + i3[None, :, None] + 0 * i3[None, None, :]
    cols = 3 * Lc.col[:, None, None] + i3[None, None, :] + 0 * i3[None, :, None]
    V = L.shape[0]
    return sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * V, 3 * V))


def normal_equations(A, b, scans, L, alpha):
    """Normal matrix ``(3V,3V)`` CSR and right-hand side ``(3V,)`` for affine maps A (M,V,3,3),
    b (M,V,3), scans (M,V,3), Laplacian L (V,V), α >= 0."""
    M, V = A.shape[:2]
    N = sp.csr_matrix((3 * V, 3 * V))
    rhs = np.zeros(3 * V)
    for m in range(M):
        D = _block_diag(A[m])
        e = (scans[m] - b[m]).ravel()
        N = N + D.T @ D
        rhs += D.T @ e
        if alpha > 0:
            P = _laplacian_times_blocks(L, A[m])
            N = N + alpha * (P.T @ P)
            rhs += alpha * (P.T @ (L @ (scans[m] - b[m])).ravel())
    return N.tocsc(), rhs


def solve_rest_vertices(model, poses, scans, L, alpha):
    """The rest vertices ``(V,3)`` minimising Q with everything else fixed (metres)."""
    A, b = affine_form(model, poses)
    N, rhs = normal_equations(A, b, np.asarray(scans, dtype=np.float64), L, alpha)
    x = spla.splu(N).solve(rhs)
    return x.reshape(-1, 3)
