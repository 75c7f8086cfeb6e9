"""The swing-weight QP: exact minimiser of ``wᵀHw − 2bᵀw`` on ``{0 ≤ w ≤ 1, Σ w ≤ 1}`` for batches of
small problems (dissertation (model-adaptive mocap) §3.4 (A): a vertex's posed position is affine in its
swing weights, so its best swing weights for fixed twist weights are a least-squares problem in k ≤ K
variables).  Closed forms for k ≤ 2, certified active sets for k ≥ 3, the enumeration of every face as
fallback and reference."""
import itertools

import numpy as np

ACTIVE_SET_MIN_K = 3   # swing QPs with fewer variables use closed forms (k = 1: the clipped parabola; k = 2: _qp_two)


def box_simplex_qp(H, b, nvar):
    """Exact minimiser of ``wᵀHw − 2bᵀw`` subject to ``0 ≤ w ≤ 1``, ``Σ w ≤ 1`` and ``w_j = 0`` for
    ``j ≥ nvar``, for a batch of small convex problems.

    H ``(N,K,K)`` symmetric PSD, b ``(N,K)``, nvar ``(N,)`` int.  Returns ``w (N,K)``.
    Method: active-set enumeration over the faces of the feasible polytope.  Because Σ w ≤ 1, a variable
    at its upper bound 1 forces all others to 0, so the faces are: the vertices ``e_j``; for every
    non-empty set S of free variables (the others 0) the unconstrained stationary point on S; and for
    |S| ≥ 2 the stationary point on S with Σ_S w = 1 (KKT system).  The feasible candidate with the least
    objective is the global minimum (convex problem; on a singular face a tiny ridge picks one of the
    equal-valued minimisers, and a feasible one of equal value exists on a smaller face).
    Problems are grouped by k.  k = 1: the clipped vertex of the parabola; k = 2: the closed form of
    :func:`_qp_two`; otherwise a few certified active-set steps per problem
    (:func:`qp_group`), the enumeration only for the problems they do not certify."""
    H = np.asarray(H, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    N, K = b.shape
    out = np.zeros((N, K))
    for k in np.unique(nvar):
        if k <= 0:
            continue
        rows = np.flatnonzero(nvar == k)
        out[rows, :k] = qp_group(H[rows][:, :k, :k], b[rows, :k])[0]
    return out


def qp_group(H, b, guesses=6):
    """:func:`box_simplex_qp` for problems that all have k = b.shape[1] variables.  Returns ``(w (N,k),
    wᵀHw − 2bᵀw (N,))``.

    k = 1 and 2 in closed form; for k ≥ ``ACTIVE_SET_MIN_K`` primal-dual active sets with a certificate
    instead of all 2·2^k − 1 faces of every problem.  Each problem has a guessed face: a free set F (the
    others 0) and whether Σ w = 1; its stationary point comes from the masked KKT system
    (:func:`_face_point`), all problems in one batched elimination per step.  A feasible point whose
    Frank-Wolfe gap (:func:`_face_value`) is at most ``1e-11 (max_j H_jj + max_j |b_j|)`` certifies its
    problem: the KKT conditions hold to rounding.  Otherwise the guess is updated (:func:`_next_face`;
    first guess: all free, no sum).  Problems not certified after ``guesses + 1`` steps get the full
    enumeration (:func:`_qp_group_enumerate`), so only the CPU time depends on ``guesses``.  The certified
    face is the one the enumeration picks (unless two faces tie: singular H, same objective but possibly
    another minimiser), so w agrees with the enumeration to rounding."""
    N, k = b.shape
    if k == 2:
        return _qp_two(H, b)
    if k < ACTIVE_SET_MIN_K:
        return _qp_group_enumerate(H, b)
    best_f = np.zeros(N)                                    # w = 0 is feasible with objective 0
    scale = np.abs(b).max(axis=1) + np.diagonal(H, axis1=1, axis2=2).max(axis=1)
    tol = 1e-11 * scale + 1e-300
    ridge = 1e-13 * (np.trace(H, axis1=1, axis2=2) / k + 1e-300)
    idx = np.flatnonzero(np.max(b, axis=1) > tol)          # the gap of w = 0 is max(0, max_j b_j)
    Ht = np.ascontiguousarray(H.transpose(1, 2, 0))         # problems last: elementwise work on rows
    bt = np.ascontiguousarray(b.T)
    bestt = np.zeros((k, N))
    free = np.ones((k, len(idx)), dtype=bool)
    on = np.zeros(len(idx), dtype=bool)
    for step in range(guesses + 1):
        if len(idx) == 0:
            break
        Hc, bc = np.take(Ht, idx, axis=2), np.take(bt, idx, axis=1)   # (k,k,n), (k,n)
        w = _face_point(Hc, bc, ridge[idx], free, on)
        feas, wc, f, g, gap = _face_value(Hc, bc, w)
        better = feas & (f < best_f[idx])
        bestt[:, idx[better]] = wc[:, better]
        best_f[idx[better]] = f[better]
        still = ~(feas & (gap <= tol[idx]))
        idx, free, on, w, g = idx[still], free[:, still], on[still], w[:, still], g[:, still]
        if len(idx) == 0 or step == guesses:
            break
        free, on = _next_face(free, on, w, g)
    best = bestt.T.copy()
    if len(idx):
        best[idx], best_f[idx] = _qp_group_enumerate(H[idx], b[idx])
    return best, best_f


def _face_point(Hc, bc, ridge, free, on):
    """Stationary points ``w (k,n)`` of n problems (problems last: ``Hc (k,k,n)``, ``bc (k,n)``) on their
    guessed faces: free variables ``free (k,n)`` (the others 0), sum constraint active where ``on (n,)``.
    Solves the masked ``(k+1)×(k+1)`` system (H + ``ridge (n,)`` on F×F, the identity on the fixed rows,
    the sum row on F if active, else the identity) by :func:`_solve_unpivoted`; a singular face gives
    non-finite entries."""
    k, n = bc.shape
    diag = np.arange(k + 1)
    m = np.concatenate([free, on[None]], axis=0)            # (k+1, n) active rows
    A = np.empty((k + 1, k + 1, n))
    A[:k, :k] = Hc
    A[diag[:k], diag[:k]] += ridge
    A[:k, k] = A[k, :k] = 1.0
    A[k, k] = 0.0
    A *= m[:, None, :] & m[None, :, :]
    A[diag, diag] += ~m
    y = np.concatenate([bc, np.ones((1, n))], axis=0) * m
    return _solve_unpivoted(A, y)[:k]


def _face_value(Hc, bc, w):
    """For face points ``w (k,n)``: ``(feasible (n,), w clipped onto the polytope (k,n), objective (n,),
    g = Hw − b (k,n), Frank-Wolfe gap (n,))``.  The gap ``gᵀw − min(0, min_j g_j)`` (g is half the gradient;
    the least gᵀv over the polytope is at a vertex 0 or e_j) bounds f − f*."""
    k, n = bc.shape
    with np.errstate(invalid="ignore"):
        feas = np.all(w >= -1e-12, axis=0) & np.all(w <= 1 + 1e-12, axis=0) & (w.sum(axis=0) <= 1 + 1e-12)
    wc = np.clip(np.where(feas, w, 0.0), 0.0, 1.0)
    wc /= np.maximum(wc.sum(axis=0), 1.0)
    Hw = np.zeros((k, n))                                   # the sums in the order of _quadratic
    for i in range(k):
        for j in range(k):
            Hw[i] += Hc[i, j] * wc[j]
    f = np.zeros(n)
    for i in range(k):
        f += wc[i] * (Hw[i] - 2.0 * bc[i])
    g = Hw - bc
    gap = np.sum(g * wc, axis=0) - np.minimum(g.min(axis=0), 0.0)
    return feas, wc, f, g, gap


def _next_face(free, on, w, g):
    """The next guess ``(free (k,n), on (n,))`` from the uncertified face points ``w (k,n)`` and ``g (k,n)``:
    drop the free variables that came out negative, else activate the sum if it exceeds 1, else release
    the sum if its multiplier is negative and free every fixed variable whose multiplier is negative.  A
    singular face toggles the sum; a face with nothing free frees everything."""
    bad = ~np.isfinite(w).all(axis=0)
    neg = free & (w < 0)                                    # drop the negative variables
    anyneg = neg.any(axis=0)
    over = ~anyneg & ~on & (np.sum(w, axis=0) > 1 + 1e-12)
    ok = ~anyneg & ~over & ~bad
    mu = np.where(on, -np.sum(np.where(free, g, 0.0), axis=0) / np.maximum(free.sum(axis=0), 1), 0.0)
    release = ok & on & (mu < 0)
    add = ok & ~free & (g + np.where(release, 0.0, mu) < 0)
    free = (free & ~neg) | add
    on = np.where(over, True, np.where(release, False, on))
    on[bad] = ~on[bad]
    free[:, ~free.any(axis=0)] = True
    return free, on


def _qp_two(H, b):
    """:func:`qp_group` for k = 2 in closed form: the unconstrained minimiser if it is feasible (convex:
    then it is the optimum), and the clipped minimisers of the parabolas along the three edges of the
    triangle (w₂ = 0, w₁ = 0, w₁ + w₂ = 1; their ends are the vertices 0, e₁, e₂); the best of them.
    The same faces with the same ridge ``1e-13 · tr(H)/2`` as :func:`_qp_group_enumerate` (its result to
    rounding), several times faster.  Returns ``(w (N,2), wᵀHw − 2bᵀw (N,))``."""
    h11, h12, h22 = H[:, 0, 0], H[:, 0, 1], H[:, 1, 1]
    b1, b2 = b[:, 0], b[:, 1]
    ridge = 1e-13 * ((h11 + h22) / 2 + 1e-300)
    a11, a22 = h11 + ridge, h22 + ridge
    W = np.zeros((len(b), 4, 2))                            # edge w2 = 0, edge w1 = 0, sum edge, interior
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        W[:, 0, 0] = b1 / a11
        W[:, 1, 1] = b2 / a22
        t = (a22 - h12 + b1 - b2) / (a11 - 2.0 * h12 + a22)     # w = (t, 1 − t)
        W[:, 2, 0], W[:, 2, 1] = t, 1.0 - t
        det = a11 * a22 - h12 * h12
        x1, x2 = (a22 * b1 - h12 * b2) / det, (a11 * b2 - h12 * b1) / det
        inside = (x1 >= -1e-12) & (x2 >= -1e-12) & (x1 + x2 <= 1 + 1e-12) & np.isfinite(x1 + x2)
    W[inside, 3, 0], W[inside, 3, 1] = x1[inside], x2[inside]
    np.clip(W, 0.0, 1.0, out=W)                             # ±inf (H ≈ 0 along the edge): its end
    W[np.isnan(W)] = 0.0                                    # 0/0: a flat edge, any point of it will do
    W /= np.maximum(W.sum(axis=2, keepdims=True), 1.0)
    w1, w2 = W[..., 0], W[..., 1]
    f = (w1 * (h11[:, None] * w1 + h12[:, None] * w2 - 2.0 * b1[:, None])
         + w2 * (h12[:, None] * w1 + h22[:, None] * w2 - 2.0 * b2[:, None]))
    c = np.argmin(f, axis=1)
    rows = np.arange(len(b))
    fc = f[rows, c]
    take = fc < 0.0                                         # else w = 0 (objective 0) is as good
    return np.where(take[:, None], W[rows, c], 0.0), np.where(take, fc, 0.0)


def _solve_unpivoted(A, y):
    """``x = A⁻¹ y`` for ``A (s,s,n)``, ``y (s,n)`` (problems last), by Gaussian elimination without
    pivoting, overwriting A and y.  Meant for the masked KKT systems of :func:`qp_group` (a positive
    definite block, then the sum row, whose pivot −1ᵀH⁻¹1 is negative): a zero pivot (singular face)
    gives non-finite entries, which the QP treats as infeasible.  Faster than batched LAPACK ``solve``
    for these tiny systems."""
    s = A.shape[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        for p in range(s - 1):
            f = A[p + 1:, p] / A[p, p]                      # (s-p-1, n)
            A[p + 1:, p + 1:] -= f[:, None, :] * A[p, p + 1:][None]
            y[p + 1:] -= f * y[p]
        x = np.empty_like(y)
        for p in range(s - 1, -1, -1):
            x[p] = (y[p] - np.einsum("qn,qn->n", A[p, p + 1:], x[p + 1:])) / A[p, p]
    return x


def _qp_group_enumerate(H, b):
    """Reference for :func:`qp_group`: every face of every problem (2·2^k − 1 candidates), all free sets
    of one size in one batched call.  Returns ``(w (N,k), wᵀHw − 2bᵀw (N,))``."""
    N, k = b.shape
    if k == 1:                                              # convex parabola on [0, 1]: clip its vertex
        h, c = H[:, 0, 0], b[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.clip(np.where(h > 0, c / h, np.where(c > 0, 1.0, 0.0)), 0.0, 1.0)
        return w[:, None], (h * w - 2.0 * c) * w
    best = np.zeros((N, k))
    best_f = np.zeros(N)                                    # w = 0 is feasible with objective 0
    ridge = 1e-13 * (np.trace(H, axis1=1, axis2=2) / k + 1e-300)

    def consider(w):                                        # w (N, C, k) candidates, feasibility checked
        feas = np.all(w >= -1e-12, axis=2) & np.all(w <= 1 + 1e-12, axis=2) & (w.sum(axis=2) <= 1 + 1e-12)
        w = np.clip(w, 0.0, 1.0)
        w /= np.maximum(w.sum(axis=2, keepdims=True), 1.0)
        f = _quadratic(w, H, b)
        f = np.where(feas, f, np.inf)
        c = np.argmin(f, axis=1)
        fc = f[np.arange(N), c]
        better = fc < best_f
        best[better] = w[better, c[better]]
        best_f[better] = fc[better]

    consider(np.broadcast_to(np.eye(k), (N, k, k)).copy())          # the vertices e_j
    for size in range(1, k + 1):
        S = np.array(list(itertools.combinations(range(k), size)))  # (C, size)
        C = len(S)
        Hs = H[:, S[:, :, None], S[:, None, :]] + ridge[:, None, None, None] * np.eye(size)   # (N,C,s,s)
        bs = b[:, S]                                                                           # (N,C,s)
        rows = np.arange(C)[:, None]
        sol = solve_small(Hs, bs[..., None])[..., 0]
        w = np.zeros((N, C, k))
        w[:, rows, S] = sol
        consider(w)
        if size >= 2:                                        # with the sum constraint active (KKT)
            KKT = np.zeros((N, C, size + 1, size + 1))
            KKT[..., :size, :size] = Hs
            KKT[..., :size, size] = KKT[..., size, :size] = 1.0
            rhs = np.concatenate([bs, np.ones((N, C, 1))], axis=2)
            sol = solve_small(KKT, rhs[..., None])[..., :size, 0]
            w = np.zeros((N, C, k))
            w[:, rows, S] = sol
            consider(w)
    return best, best_f


def _quadratic(w, H, b):
    """``wᵀHw − 2bᵀw`` ``(N,C)`` for candidates ``w (N,C,k)``, ``H (N,k,k)``, ``b (N,k)`` (k small)."""
    k = w.shape[2]
    f = np.zeros(w.shape[:2])
    for i in range(k):
        Hw = np.zeros(w.shape[:2])
        for j in range(k):
            Hw += H[:, None, i, j] * w[..., j]
        f += w[..., i] * (Hw - 2.0 * b[:, None, i])
    return f


def solve_small(A, B):
    """``X = A⁻¹ B`` for a batch of small systems ``A (...,s,s)``, ``B (...,s,r)``: closed forms (Cramer /
    adjugate) for s ≤ 3, LAPACK otherwise.  A singular system gives non-finite entries (no exception);
    the QP treats those candidates as infeasible."""
    s = A.shape[-1]
    if s > 3:
        return np.linalg.solve(A, B)
    with np.errstate(divide="ignore", invalid="ignore"):
        if s == 1:
            return B / A
        if s == 2:
            a, b_, c, d = A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]
            det = (a * d - b_ * c)[..., None]
            x0 = (d[..., None] * B[..., 0, :] - b_[..., None] * B[..., 1, :]) / det
            x1 = (a[..., None] * B[..., 1, :] - c[..., None] * B[..., 0, :]) / det
            return np.stack([x0, x1], axis=-2)
        r0, r1, r2 = A[..., 0, :], A[..., 1, :], A[..., 2, :]
        c0, c1, c2 = np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)    # columns of adj(A)
        det = np.sum(r0 * c0, axis=-1)[..., None, None]
        inv = np.stack([c0, c1, c2], axis=-1) / det
        return inv @ B

