"""At most k bones per vertex for a linear-blend skin (glTF keeps 4 influences, game engines 4 or 8):
the best k bones and weights per vertex, fitted to target positions over sample poses, instead of
keeping the k largest weights and renormalising (:func:`truncate`).

Per vertex v with candidate bones j (the bones of its unlimited weights), pose n maps the rest vertex to
``p_nj = Rm_nj v + tm_nj``; with weights w (w >= 0, Σ w = 1) the skinned position is Σ_j w_j p_nj, so its
error from the target y_n is Σ_j w_j (p_nj − y_n) = D_n w.  The fit minimises Σ_n |D_n w|² = wᵀ G w with
G = Σ_n D_nᵀ D_n (candidates × candidates), over supports of at most k candidates.  On a support S
without the sign constraint the minimiser is w = G_S⁻¹1 / (1ᵀG_S⁻¹1) with cost 1 / (1ᵀG_S⁻¹1); the
constrained optimum on a k-support is the equality-constrained optimum of one of its sub-supports, so
enumerating every support of 1..k candidates and keeping the cheapest with w >= 0 is the exact optimum
(no worse than truncation, whose support is among them).  Supports are enumerated once per candidate
count for all vertices with that count (batched solves); a vertex with more than ``max_candidates``
candidates keeps its largest ones.
"""
from itertools import combinations
from math import comb

import numpy as np

from ..errors import ArticulaInputError

SUBSET_BUDGET = 5000          # supports enumerated per vertex at most (limits the candidate count)
BATCH_ELEMENTS = 4_000_000    # floats of stacked (vertices × supports × s × s) systems per batch


def truncate(weights, k: int) -> np.ndarray:
    """Keep the ``k`` largest weights of each row of ``weights (V, J)`` and rescale them to sum to the
    row's old sum (truncate-and-renormalise, what exporters do); k = 0 returns a copy."""
    W = np.array(weights, dtype=np.float64)
    if k <= 0 or k >= W.shape[1]:
        return W
    drop = np.argsort(-W, axis=1, kind="stable")[:, k:]
    total = W.sum(axis=1)
    np.put_along_axis(W, drop, 0.0, axis=1)
    kept = W.sum(axis=1)
    scale = np.divide(total, kept, out=np.ones_like(total), where=kept > 0)
    return W * scale[:, None]


def max_candidates(k: int, budget: int = SUBSET_BUDGET) -> int:
    """The largest candidate count m whose supports of 1..k bones number at most ``budget`` (>= k)."""
    m = k
    while sum(comb(m + 1, s) for s in range(1, k + 1)) <= budget:
        m += 1
    return m


def candidates(weights, k: int):
    """Candidate bones of the vertices with more than ``k`` non-zero weights: ``(rows (R,), cand (R, M))``,
    each row's bones by decreasing weight, padded with -1; at most :func:`max_candidates` per row."""
    W = np.asarray(weights)
    counts = (W > 0).sum(axis=1)
    rows = np.flatnonzero(counts > k)
    M = min(int(counts.max(initial=0)), max_candidates(k))
    order = np.argsort(-W[rows], axis=1, kind="stable")[:, :M]
    cand = np.where(np.take_along_axis(W[rows], order, axis=1) > 0, order, -1)
    return rows, cand


def add_gram(G, rest, cand, Rm, tm, targets) -> None:
    """Add Σ_n D_nᵀ D_n to ``G (R, M, M)`` for poses ``Rm (N, J, 3, 3)``, ``tm (N, J, 3)``: rest vertices
    ``rest (R, 3)``, candidate bones ``cand (R, M)`` (-1 = none, its column stays zero) and target
    positions ``targets (N, R, 3)``.  Metres²."""
    safe = np.maximum(cand, 0)
    for n in range(len(Rm)):
        p = np.einsum("rmij,rj->rmi", Rm[n][safe], rest) + tm[n][safe]         # (R, M, 3)
        D = np.where(cand[..., None] >= 0, p - targets[n][:, None, :], 0.0)
        G += np.einsum("rmi,rli->rml", D, D)


def _solve_supports(G, subsets):
    """Equality-constrained optimum on every support: weights ``(R, C, s)`` and costs ``(R, C)``.  A tiny
    ridge (1e-12 of the largest diagonal entry) keeps coinciding bones solvable."""
    Gs = G[:, subsets[:, :, None], subsets[:, None, :]]                           # (R, C, s, s)
    ridge = 1e-12 * np.einsum("rii->ri", G).max(axis=1) + 1e-30
    Gs = Gs + ridge[:, None, None, None] * np.eye(subsets.shape[1])
    x = np.linalg.solve(Gs, np.ones(Gs.shape[:3] + (1,)))[..., 0]                # G_S⁻¹ 1
    total = x.sum(axis=2)
    total = np.where(total > 0, total, np.nan)
    return x / total[..., None], 1.0 / total


def best_weights(G, cand, k: int) -> np.ndarray:
    """Weights ``(R, M)`` over the candidates (``cand`` -1 = none): at most ``k`` non-zero, >= 0, summing
    to 1, minimising wᵀ G w exactly (module docstring)."""
    if k < 1:
        raise ArticulaInputError(f"max influences must be >= 1 to optimise, got {k}")
    R, M = cand.shape
    out = np.zeros((R, M))
    best = np.full(R, np.inf)
    count = (cand >= 0).sum(axis=1)
    for m in np.unique(count):
        rows = np.flatnonzero(count == m)
        for s in range(1, min(k, m) + 1):
            subsets = np.array(list(combinations(range(m), s)))
            step = max(1, BATCH_ELEMENTS // (len(subsets) * s * s))
            for r0 in range(0, len(rows), step):
                sel = rows[r0:r0 + step]
                w, cost = _solve_supports(G[sel], subsets)
                cost = np.where((w >= -1e-9).all(axis=2) & np.isfinite(cost), cost, np.inf)
                pick = np.argmin(cost, axis=1)
                c = cost[np.arange(len(sel)), pick]
                better = c < best[sel]
                upd = sel[better]
                best[upd] = c[better]
                rowsw = np.zeros((len(upd), M))
                np.put_along_axis(rowsw, subsets[pick[better]], w[better, pick[better]], axis=1)
                out[upd] = rowsw
    out = np.clip(out, 0.0, None)                  # one-bone supports are always feasible: no empty row
    return out / out.sum(axis=1, keepdims=True)
