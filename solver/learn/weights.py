"""Twist and swing weights by sampling-based block coordinate descent (spec §3.4 (A), anchors §1.5).

Each vertex v has an anchor part a and twist/swing weights on the children C(a) of its anchor.
For one vertex, with everything else fixed, Q depends on its posed positions p_v,m only through its data
term and the Laplacian rows that contain it (its own and its one-ring's).  Completing the square,
``Q(p') = κ_v Σ_m ‖p'_m − g_v,m‖² + const`` with ``κ_v = 1 + α Σ_n L[n,v]²`` and
``g_v = (s_v − α[(Lᵀ r)_v − (Σ_n L[n,v]²) p_v]) / κ_v`` (r = L p − L s, the current Laplacian residuals),
so the exact gain of moving vertex v alone from p to p' is ``κ_v Σ_m (‖p_m − g_m‖² − ‖p'_m − g_m‖²)``.

Candidates for the twist weights (δ ∈ ``steps``, default 0.2, 0.1, 0.05, 0.02; the larger ones only where
the smallest gains, see "Coarse-to-fine steps" below):
* stay (only the swing weights are re-solved);
* slide along the chain: ``w_c ± δ`` for each child c of the anchor (clipped to [0,1], sum ≤ 1; the
  neutral remainder absorbs the change);
* at forks, move δ from one child to another;
* backward past the anchor (only if the vertex has no twist weight): anchor ← parent, weight 1 − δ (and
  exactly 1: the same transform) on the old anchor's joint;
* forward (only if one twist weight is 1): anchor ← that child with all weights 0 (the same transform),
  optionally δ on one of its children.
For each candidate the swing weights on the candidate anchor's children are the exact minimiser of the
vertex's Q (a least-squares problem in ≤ K variables with 0 ≤ w ≤ 1, Σ w ≤ 1) by :func:`box_simplex_qp`
(the posed position is affine in the swing weights: its columns are the twisted point under k+1
affine maps).

Blocks: the vertices are coloured so that two vertices within two rings never share a colour; a block
is one colour class.  Its vertices have disjoint Laplacian rows, so their gains add exactly: each is
evaluated against the current residuals (incremental: only g of the block is recomputed, from the
residuals that earlier blocks updated in place) and every improving one takes its best candidate.
A sweep visits all classes (cyclic BCD rather than a global best-gain heap: every vertex is updated
once per sweep at the cost of one vectorised evaluation per class).  The objective decreases by
exactly the sum of the applied gains (checked by the tests against a full recomputation).

Joint move (before the classes of every sweep, :func:`joint_move`): with α = 100 a lone vertex move is
penalised by its one-ring's Laplacian rows, so single-vertex blocks creep.  Every vertex proposes its
best data-only candidate and the proposals are applied together (all, else the best half, else a
quarter) only if the exactly recomputed Q decreases.  Measured on the tube body from binary weights,
5 sweeps: Q 0.0007 with it vs 0.023 without; error reduction 98 % vs 72 %.  Once rejected it is not
tried again in the same :func:`optimise_weights` call: late in the alternation it never gains (MakeHuman,
19 parts: rejected at the first try from the third call on, 1.1 s of a 2.6 s sweep; same objective log).

Coarse-to-fine steps (not in the spec; :func:`evaluate`): each vertex is first offered every move with the
smallest step (and the moves without a step); the larger steps are offered only along the directions
(a child's weight up or down, a fork pair, backward, forward onto a grandchild: :func:`candidates`) whose
smallest step gains.  A direction whose small step loses is thus never tried at 0.2, which the smooth
dependence of Q on one twist weight makes rare to matter.  Measured on captured calls of MakeHuman
game_engine female,heavy hybrid (19 parts; its learned root has 4 children and anchors 5,591 of the 13,380
vertices, whose candidates are 63 % of all), old and new in the same session, one solver thread: a main
round (α = 100, 3 sweeps) 5.4-5.5 → 3.7-3.9 s with the same Q log (29.266796); the first warm-start round
(from binary weights) 9.5-10.3 → 5.2-5.7 s, Q 21.740106 → 21.740555 (+2e-5 relative).

Step pruning (not in the spec): within one :func:`optimise_weights` call, a step δ that won fewer than
``STEP_MIN_SHARE`` (1 %) of a sweep's twist-changing moves is not offered in the following sweeps (the
smallest step always is; with the coarse-to-fine evaluation a pruned step is not widened to).  The
measurement below predates the coarse-to-fine steps.  Measured on MakeHuman (19 parts, the second main round at α = 100, 3 sweeps):
of 37,400 applied moves 34,253 only re-solved the swing weights, 1,752 moved a twist weight by 0.02,
77 by 0.05, 9 by 0.1 and 7 by 0.2 (1,292 changed the anchor); with pruning the call took 3.1 instead of
3.9-4.2 s and ended at Q 25.621951 instead of 25.621874.  From binary weights (the first warm-start
round) every step keeps winning and nothing is pruned (the same log).

Halves in parallel (not in the spec; :meth:`TwoRing.halves`, :func:`_halves_in_parallel`).  Colour classes
of a few hundred vertices are too small for two threads (the evaluation is mostly interpreter work), so a
sweep is cut in space instead: breadth-first levels from a pseudo-peripheral vertex split the mesh into
half_a (levels < l), a band (levels l, l + 1) and half_b (levels ≥ l + 2), l balancing the dirty
vertices' cost.  Vertices of different halves are three or more edges apart, outside each other's two-ring,
so neither half's targets depend on the other's moves and their residual rows are disjoint: visiting the
classes on half_a in a forked child (:class:`parallel.ForkedCall`, Linux) while this process visits them on
half_b, then the band, is exactly the serial visit half_a, half_b, band (the tests compare both paths).
The joint move's data-only proposals are likewise computed half in the child.  Only sweeps with at least
``SPLIT_MIN_WORK`` dirty vertex-scans per class are cut (on Dem Bones' 754-vertex Bone_Anim the classes
hold ~40 vertices and the extra calls cost more than the second core gains), and only where a child can
be forked: visited in one process the cut sweep is slower than the plain one (more, smaller calls).
numpy's BLAS runs on one thread in :func:`optimise_weights` (:func:`solver.parallel.single_blas_thread`, as in
all of learn_rig).  Measured on MakeHuman game_engine male,thin hybrid (13,380 vertices × 30 scans, 19
parts; band 515 vertices, halves 6,386 / 6,479), whole learn_rig, same host period: weights stage 32.3 s
before, 27.8 s with the child, 39.8 s cut but in one process; per main-round sweep half_b 0.70-0.91 s here,
half_a 0.81-1.29 s in the child, 0.05-0.58 s waiting for it (result ~10 MB through a pipe), the band
0.15-0.39 s.  The Q logs are the same with and without the child.  The band is coloured on its own
(:func:`_subset_classes`: 10 classes instead of the 14 of the mesh's colouring cut down to it).

Active set (:class:`_Tracker`; exact, so the Q log does not change).  A vertex's data-only proposal
depends only on its own anchor and weights, so the joint move recomputes only the proposals of vertices
that changed since.  Its BCD evaluation depends on its own state and on its targets g, i.e. on the
posed positions of its two-ring; a vertex whose last evaluation found nothing to gain, and none of
whose two-ring has changed since, would find nothing again and is skipped.  On the MakeHuman scans
this skips only 3-15 % of the evaluations: almost every vertex gains a little every sweep, if only by
re-solving its swing weights.

Evaluation (:func:`evaluate`, cost per candidate).  Candidates are grouped by candidate anchor a
(:class:`CandidateSkin`): the per-scan maps M_a and S_c − M_a are stacked into one ``(3(k+1), 4)``
matrix per scan and applied to all of the group's twisted points by one batched product, in a
``(M, component, candidate)`` layout so that elementwise work runs over contiguous rows.  The twist
blend of an anchor with one child (60 % of the candidates on the MakeHuman rig) is a rotation about
that child's fixed axis by a blended half-angle (:func:`_twist_one`, closed form); with more children
it is the component-wise DLB with the running hemisphere rule of ``hybrid_skin``.  Screening
(:func:`_screen`) ranks candidates by ``κ (‖r‖² + wᵀHw − 2bᵀw)`` from the normal equations and the
QP's own value (1-variable QPs in closed form), without forming posed positions.  Only each vertex's
best candidate is then posed with its float32-stored weights and its gain recomputed as
``f_cur − κ‖p − g‖²`` (:func:`_exact`).  The booked gains are therefore exact.
Measured (MakeHuman female, 13,380 vertices × 30 scans, 19 bones, from binary weights, process CPU
on a shared 2-core machine, old and new in the same run): 3 sweeps 2.4-3.0 s vs 19-21 s before
(0.8-1.0 s vs 5.6-7 s per sweep).  The Q log is the same, 231.159, 221.670, 218.248 (full recomputation
218.247626 for both).
Many scans (Dem Bones' Bone_Anim, 754 vertices × 400 frames): the per-candidate work is elementwise on
``(M, n)`` arrays, so candidates are skinned in blocks of ``BLOCK / M`` (each temporary ≤ 512 KiB, in
cache); the blend of k ≥ 2 twists is one matrix product (:func:`_twist_blend`); :func:`_twist_one` works
in place; per-vertex targets are gathered with ``np.take`` (``g[:, :, idx]`` returns a non-contiguous
array, and the subtraction that follows was 5-10x slower at M = 400).  Measured (process CPU of all
optimise_weights calls of one learn_rig, α = 1, old and new on the same inputs in the same run): Bone_Anim
10 parts 9.4 s -> 7.7 s, 20 parts 12.9 s -> 10.7 s; MakeHuman (19 parts, α = 100) 26.5 s -> 24.5 s.  The Q
logs agree to 4e-16 relative (rounding of the k ≥ 2 blend).
Tried and not kept: applying the blended dual quaternions in place (no gain); the base and swing columns
by broadcasting instead of the batched product (3-10x slower).
Screening in float32 (not kept either).  Residuals are ~1e-4 m against coordinates up to 1.6 m, so
the screened gains err by 4e-7 (median) to 5e-6 (90th percentile), as large as the gains themselves
(median 4e-6); Q after 3 sweeps 218.378 instead of 218.248.  A gain floor of 1e-9 Q (smaller moves not
applied, so their two-rings stay clean): 25 % less CPU per sweep, but Q after 3 sweeps 218.276.  Removing
duplicate candidates: only 5 % are duplicates.
Swing QP (:func:`_qp_group`): certified primal-dual active sets for k ≥ 3 instead of enumerating all
2·2^k − 1 faces (kept as :func:`_qp_group_enumerate`: k = 1, the reference, and the problems the
active sets do not certify); k = 2 in closed form (:func:`_qp_two`).  Measured (MakeHuman game_engine
female,heavy, hybrid, 13,380 vertices × 30 scans, 19 parts, whole learn_rig, process CPU, old and new
run side by side): weights stage 62.3 s -> 36.3 s, learn_rig 93.1 s -> 69.0 s; the objective logs agree
to 4e-14 relative.
"""
import itertools

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from .. import parallel
from ..errors import Cancelled  # noqa: F401  (raised by progress callbacks)
from ..parallel import single_blas_thread
from ..rig.model import Model
from ..rig.skinning import bone_terms, hybrid_skin, running_flips

STEPS = (0.2, 0.1, 0.05, 0.02)
ACTIVE_SET_MIN_K = 3   # swing QPs with fewer variables use closed forms (k = 1: the clipped parabola; k = 2: _qp_two)
PARALLEL_MIN_WORK = 60_000    # vertex-scans per thread of one evaluation (less: one thread; smaller pieces
                              # lose more to the interpreter lock than the second thread gains)
STEP_MIN_SHARE = 0.01  # a step δ is offered again in a call's next sweep if it won this share of the moves
SPLIT_MIN_WORK = 10_000   # dirty vertex-scans per colour class below which a sweep is not cut into halves
                          # (each evaluate call costs ~5 ms of Python, ~1,400 vertex-scans' worth)
MIN_GAIN = 1e-15       # a move is applied only if it gains more than this fraction of Q
BLOCK = 2 ** 16        # scan-candidates (M · candidates) per skinning block: each (M, n) temporary is at
                       # most 512 KiB and stays in cache; 2184 candidates at M = 30, 163 at M = 400


def _block(M):
    """Candidates per skinning block for M scans (see ``BLOCK``)."""
    return max(64, BLOCK // max(M, 1))


# ----------------------------------------------------------------------------- the swing QP

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
    (:func:`_qp_group`), the enumeration only for the problems they do not certify."""
    H = np.asarray(H, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    N, K = b.shape
    out = np.zeros((N, K))
    for k in np.unique(nvar):
        if k <= 0:
            continue
        rows = np.flatnonzero(nvar == k)
        out[rows, :k] = _qp_group(H[rows][:, :k, :k], b[rows, :k])[0]
    return out


def _qp_group(H, b, guesses=6):
    """:func:`box_simplex_qp` for problems that all have k = b.shape[1] variables.  Returns ``(w (N,k),
    wᵀHw − 2bᵀw (N,))``.

    Primal-dual active sets with a certificate instead of all 2·2^k − 1 faces of every problem.  Each
    problem has a guessed face: a free set F (the others 0) and whether Σ w = 1.  Its stationary point
    solves the masked ``(k+1)×(k+1)`` system (H + ridge on F×F, the identity on the fixed rows, the
    sum row 1 on F if active, else the identity), all problems in one batched elimination per step
    (:func:`_solve_unpivoted`, problems-last layout so that all elementwise work runs on rows).  A
    candidate certifies its problem if it is feasible and its Frank-Wolfe gap ``gᵀw − min(0, min_j g_j)``
    (g = Hw − b, half the gradient; the least gᵀv over the polytope is at a vertex 0 or e_j) is at most
    ``1e-11 (max_j H_jj + max_j |b_j|)``: the KKT conditions hold to rounding (the gap bounds f − f*).
    Guess update (first guess: all free, no sum): drop the free variables that came out negative, else
    activate the sum if it exceeds 1, else release the sum if its multiplier is negative and free every
    fixed variable whose multiplier is negative.  Problems not certified after ``guesses + 1`` steps get
    the full enumeration (:func:`_qp_group_enumerate`), so only the CPU time depends on the guesses.
    The certified face is the one the enumeration picks (unless two faces tie: singular H, where both
    give the same objective but possibly another minimiser); its candidate is computed by elimination
    on the masked system instead of the closed forms / LAPACK, so w agrees to rounding.
    Measured on 170 sampled k = 4 calls of the MakeHuman run below (334,124 problems, ~2,000 per call,
    cond(H) median 33, max 3,200): 0.45-0.56 s vs 2.6-2.7 s CPU for the enumeration, |Δw| ≤ 7e-16,
    |Δf| ≤ 8e-16 relative; after 3 / 4 / 5 steps 0.9 % / 0.14 % / 0.02 % of the problems are open,
    82 (0.02 %) need the enumeration.  k = 3 (random problems): 4.2 vs 5.3 ms per 1,500; k = 2: slower
    than the closed forms, hence ``ACTIVE_SET_MIN_K``."""
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
    diag = np.arange(k + 1)
    for step in range(guesses + 1):
        if len(idx) == 0:
            break
        n = len(idx)
        Hc, bc = np.take(Ht, idx, axis=2), np.take(bt, idx, axis=1)   # (k,k,n), (k,n)
        m = np.concatenate([free, on[None]], axis=0)        # (k+1, n) active rows
        A = np.empty((k + 1, k + 1, n))
        A[:k, :k] = Hc
        A[diag[:k], diag[:k]] += ridge[idx]
        A[:k, k] = A[k, :k] = 1.0
        A[k, k] = 0.0
        A *= m[:, None, :] & m[None, :, :]
        A[diag, diag] += ~m
        y = np.concatenate([bc, np.ones((1, n))], axis=0) * m
        w = _solve_unpivoted(A, y)[:k]                      # (k, n)
        with np.errstate(invalid="ignore"):
            feas = np.all(w >= -1e-12, axis=0) & np.all(w <= 1 + 1e-12, axis=0) & (w.sum(axis=0) <= 1 + 1e-12)
        wc = np.clip(np.where(feas, w, 0.0), 0.0, 1.0)
        wc /= np.maximum(wc.sum(axis=0), 1.0)
        Hw = np.zeros((k, n))                               # the sums in the order of _quadratic
        for i in range(k):
            for j in range(k):
                Hw[i] += Hc[i, j] * wc[j]
        f = np.zeros(n)
        for i in range(k):
            f += wc[i] * (Hw[i] - 2.0 * bc[i])
        g = Hw - bc
        gap = np.sum(g * wc, axis=0) - np.minimum(g.min(axis=0), 0.0)
        better = feas & (f < best_f[idx])
        bestt[:, idx[better]] = wc[:, better]
        best_f[idx[better]] = f[better]
        still = ~(feas & (gap <= tol[idx]))
        idx, free, on, w, g = idx[still], free[:, still], on[still], w[:, still], g[:, still]
        if len(idx) == 0 or step == guesses:
            break
        bad = ~np.isfinite(w).all(axis=0)
        neg = free & (w < 0)                                # drop the negative variables
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
    best = bestt.T.copy()
    if len(idx):
        best[idx], best_f[idx] = _qp_group_enumerate(H[idx], b[idx])
    return best, best_f


def _qp_two(H, b):
    """:func:`_qp_group` for k = 2 in closed form: the unconstrained minimiser if it is feasible (convex:
    then it is the optimum), and the clipped minimisers of the parabolas along the three edges of the
    triangle (w₂ = 0, w₁ = 0, w₁ + w₂ = 1; their ends are the vertices 0, e₁, e₂); the best of them.
    The same faces with the same ridge ``1e-13 · tr(H)/2`` as :func:`_qp_group_enumerate` (its result to
    rounding) in about a fifth of its time (2,000 problems 0.3-0.5 vs 2.0-2.8 ms, 50 problems 0.08 vs
    0.3 ms).  Returns ``(w (N,2), wᵀHw − 2bᵀw (N,))``."""
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
    pivoting, overwriting A and y.  Meant for the masked KKT systems of :func:`_qp_group` (a positive
    definite block, then the sum row, whose pivot −1ᵀH⁻¹1 is negative): a zero pivot (singular face)
    gives non-finite entries, which the QP treats as infeasible.  ~4x faster than batched LAPACK
    ``solve`` for 5×5 systems at n = 2000."""
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
    """Reference for :func:`_qp_group`: every face of every problem (2·2^k − 1 candidates), all free sets
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


# ----------------------------------------------------------------------------- candidates

def _children_table(parents):
    B = len(parents)
    kids = [np.flatnonzero(parents == b) for b in range(B)]
    K = max(1, max(len(k) for k in kids))
    table = np.full((B, K), -1, dtype=np.int64)
    for b, k in enumerate(kids):
        table[b, :len(k)] = k
    return table


def candidates(anchor, twist, parents, steps=STEPS):
    """Twist-weight candidates of a set of vertices.

    anchor (n,), twist (n,B) float64.  Yields ``(anchor' (n,), twist' (n,B), valid (n,) bool, direction)``
    per candidate slot (see the module doc for the moves).  direction (int) names the move without its
    step δ — the same for ``w_c + 0.02`` and ``w_c + 0.2`` — and is −1 for the moves that have no step
    (stay, the re-expressions backward and forward at weight 1); :func:`evaluate` widens the steps along
    the directions whose smallest step gains."""
    n, B = twist.shape
    kids = _children_table(parents)
    K = kids.shape[1]
    rows = np.arange(n)
    ck = kids[anchor]                                            # (n,K) children of the anchor
    cur = np.where(ck >= 0, twist[rows[:, None], np.maximum(ck, 0)], 0.0)
    total = cur.sum(axis=1)
    yield anchor, twist, np.ones(n, dtype=bool), -1              # stay: swing only
    direction = itertools.count()
    for j in range(K):
        c = ck[:, j]
        for sign in (1.0, -1.0):
            way = next(direction)
            for d in steps:
                new = np.clip(cur[:, j] + sign * d, 0.0, 1.0)
                valid = (c >= 0) & (new != cur[:, j]) & (total - cur[:, j] + new <= 1.0 + 1e-9)
                tw = twist.copy()
                tw[rows[valid], c[valid]] = new[valid]
                yield anchor, tw, valid, way
    for j, j2 in itertools.permutations(range(K), 2):
        c, c2 = ck[:, j], ck[:, j2]
        way = next(direction)
        for d in steps:
            amount = np.minimum(d, np.minimum(cur[:, j], 1.0 - cur[:, j2]))
            valid = (c >= 0) & (c2 >= 0) & (amount > 0)
            tw = twist.copy()
            tw[rows[valid], c[valid]] -= amount[valid]
            tw[rows[valid], c2[valid]] += amount[valid]
            yield anchor, tw, valid, way
    par = parents[anchor]
    back_ok = (par >= 0) & (total == 0)
    way = next(direction)
    for d in (0.0,) + tuple(steps):
        tw = np.zeros_like(twist)
        tw[rows[back_ok], anchor[back_ok]] = 1.0 - d
        yield np.where(back_ok, par, anchor), tw, back_ok.copy(), way if d else -1
    full = cur >= 1.0 - 1e-6
    fwd_ok = full.any(axis=1)
    target = np.where(fwd_ok, ck[rows, np.argmax(full, axis=1)], anchor)
    yield target, np.zeros_like(twist), fwd_ok.copy(), -1
    gk = kids[target]
    for j in range(K):
        way = next(direction)
        for d in steps:
            valid = fwd_ok & (gk[:, j] >= 0)
            tw = np.zeros_like(twist)
            tw[rows[valid], gk[valid, j]] = d
            yield target, tw, valid, way


# ----------------------------------------------------------------------------- candidate list

def _candidate_list(anchor, twist, parents, steps=STEPS):
    """All valid candidates of a set of n vertices, flattened: ``(v (c,) index into the set, anchor (c,),
    twist (c,B) float32, direction (c,))`` (see :func:`candidates`; the weights are stored as float32, so
    candidates are evaluated as such)."""
    cv, ca, ct, cd = [], [], [], []
    for a, tw, valid, way in candidates(anchor, twist.astype(np.float64), parents, steps):
        sel = np.flatnonzero(valid)
        cv.append(sel)
        ca.append(a[sel])
        ct.append(tw[sel])
        cd.append(np.full(len(sel), way))
    return np.concatenate(cv), np.concatenate(ca), np.concatenate(ct).astype(np.float32), np.concatenate(cd)


def _widened(anchor, twist, parents, v, way, steps):
    """The candidates with the larger ``steps`` along the directions ``way (r,)`` of the vertices
    ``v (r,)`` (indices into ``anchor (n,)``, ``twist (n,B)``; a vertex may appear once per direction).
    Returns ``(v, anchor, twist f32)`` of :func:`_candidate_list`'s layout."""
    rv, ra, rt, rd = _candidate_list(anchor[v], twist[v], parents, steps)
    keep = rd == way[rv]
    return v[rv[keep]], ra[keep], rt[keep]


def _by_label(labels, block=None):
    """``(label, rows)`` for each distinct value of ``labels (c,)`` (rows ascending), in pieces of at most
    ``block`` rows when given."""
    order = np.argsort(labels, kind="stable")
    cuts = np.flatnonzero(np.diff(labels[order])) + 1
    for rows in np.split(order, cuts):
        step = block or max(len(rows), 1)
        for s in range(0, len(rows), step):
            yield int(labels[rows[0]]), rows[s:s + step]


# ----------------------------------------------------------------------------- candidate skinning
# Layout: scan-major, component in the middle, candidates last — ``(M, comp, n)`` — so the per-scan maps
# are applied to all candidates of one anchor by one batched matrix product per scan and every
# elementwise operation runs over contiguous rows of n candidates.

def _dq_apply_soa(b, x, out):
    """Blended twist dual quaternions given as components ``b`` (list of 8 ``(M,n)`` arrays; b[4], the
    real part of the dual half, is 0 for rotations about a point and not read) applied to rest points
    ``x (3,n)``, written to ``out (M,3,n)``.  The normalising formula of :func:`dualquat.dq_apply` with
    q = (w, u), dual vector d and s = 2/|q|²: ``x + s (u × (u × x + w x + d) + w d)``."""
    w, u0, u1, u2, _, d0, d1, d2 = b
    s = 2.0 / (w * w + u0 * u0 + u1 * u1 + u2 * u2)
    x0, x1, x2 = x
    y0 = u1 * x2 - u2 * x1 + w * x0 + d0
    y1 = u2 * x0 - u0 * x2 + w * x1 + d1
    y2 = u0 * x1 - u1 * x0 + w * x2 + d2
    out[:, 0] = x0 + s * (u1 * y2 - u2 * y1 + w * d0)
    out[:, 1] = x1 + s * (u2 * y0 - u0 * y2 + w * d1)
    out[:, 2] = x2 + s * (u0 * y1 - u1 * y0 + w * d2)


_DQ_PARTS = (0, 1, 2, 3, 5, 6, 7)          # non-zero components of twist dual quaternions


def _twist_blend(q, wt):
    """``identity (1 − Σ w) + Σ_c s_c w_c q_c`` as 8 components ``(M,n)`` (component 4 is None: zero) for
    the twist dual quaternions of an anchor's children ``q (M,8,k)`` and weights ``wt (k,n)``, with the
    running hemisphere rule of :mod:`solver.rig.skinning` for k ≥ 2: s_c = −1 where q_c's real part points
    away from the sum so far, starting from the neutral's share (which can be −1e-8 when float32 weights
    sum to just over 1: the rule then flips the first child, as ``hybrid_skin`` does).

    The signs come from :func:`solver.rig.skinning.running_flips` (scans as its frames, candidates as its
    vertices), the blend is one matrix product ``(7M, k) @ (k, n)`` with the unsigned weights plus a
    correction where a sign is −1 (rare): for k = 2 about 15 instead of 60 passes over ``(M,n)`` arrays.
    Same values up to rounding (≤ 1e-15 here, ≤ 1e-11 relative in the Q log).  Measured (M = 400, k = 2, n = 100-300,
    one thread): 0.43-0.74 ms vs 3.0-8.2 ms."""
    M, _, k = q.shape
    n = wt.shape[1]
    rest = 1 - wt.sum(axis=0)
    flips = running_flips(q[:, :4].transpose(0, 2, 1), wt.T) if k >= 2 else [None] * k   # (M,n) masks
    parts = np.ascontiguousarray(q[:, _DQ_PARTS].transpose(1, 0, 2)).reshape(len(_DQ_PARTS) * M, k)
    blend = (parts @ wt).reshape(len(_DQ_PARTS), M, n)
    blend[0] += rest
    for j, flip in enumerate(flips):
        if flip is not None:
            corr = np.where(flip, -2.0 * wt[j], 0.0)
            for c in range(len(_DQ_PARTS)):
                blend[c] += q[:, _DQ_PARTS[c], j, None] * corr
    out = [None] * 8
    for c, i in enumerate(_DQ_PARTS):
        out[i] = blend[c]
    return out


def _twist_one(x, w, centre, axis, cos_half, sin_half, out):
    """The twist blend for an anchor with one child, in closed form: ``identity (1 − w) + w q`` with q the
    rotation by φ about the child's fixed twist axis through its head is, normalised, the rotation about
    that axis by θ with ``(cos θ/2, sin θ/2) ∝ (1 − w + w cos φ/2, w sin φ/2)`` (the same dual quaternion
    as :func:`_twist_blend` + :func:`_dq_apply_soa`, in about half the operations).

    x ``(3,n)`` rest points, w ``(n,)`` twist weights, centre, axis ``(3,)`` (unit), cos_half, sin_half
    ``(M,)`` per scan.  Writes the twisted points to ``out (M,3,n)``."""
    xc = x - centre[:, None]
    p = xc - axis[:, None] * (axis @ xc)                              # component normal to the axis
    q = np.stack([axis[1] * p[2] - axis[2] * p[1], axis[2] * p[0] - axis[0] * p[2],
                  axis[0] * p[1] - axis[1] * p[0]])                     # axis × p (as np.cross)
    on_axis = x - p
    r0 = (cos_half - 1)[:, None] * w                                 # (M,n); in place from here on
    r0 += 1
    s = sin_half[:, None] * w
    cos = r0 * r0                                                    # r0², then cos θ
    s2 = s * s
    inv = cos + s2
    np.divide(1, inv, out=inv)
    cos -= s2
    cos *= inv
    sin = r0
    sin *= 2                                                         # 2 r0 s / (r0² + s²)
    sin *= s
    sin *= inv
    tmp = s2
    for i in range(3):
        o = out[:, i]
        np.multiply(cos, p[i], out=o)
        o += on_axis[i]
        np.multiply(sin, q[i], out=tmp)
        o += tmp


class CandidateSkin:
    """Posed positions of single vertices under candidate anchors/weights, from the per-(scan, bone) terms
    of :func:`solver.rig.skinning.bone_terms` computed once (skeleton and poses are fixed during BCD).

    For a vertex x with anchor a, twist weights w_t and swing weights w_s on C(a):
    ``v_t = DLB(identity + Σ_c w_t,c (dq_c − identity)) x`` and
    ``p = M_a(v_t) + Σ_c w_s,c (S_c(v_t) − M_a(v_t))`` with ``S_c = M_parent(c) ∘ Swing_c`` — the hybrid skin
    of ARCHITECTURE.md, affine in w_s; ``S_c − M_a`` is itself one affine map.  Candidates are evaluated
    per anchor (:meth:`columns`): M_a and the k maps S_c − M_a are stacked into one ``(3(k+1), 4)`` matrix
    per scan and applied to all the group's twisted points by one batched product.  (Checked against
    ``hybrid_skin`` in the tests.)"""

    def __init__(self, skeleton, poses):
        t = bone_terms(skeleton, poses)
        parents = np.asarray(skeleton.parents)
        self.kids = [np.flatnonzero(parents == b) for b in range(len(parents))]
        self.K = _children_table(parents).shape[1]
        self.M, B = t["twist_dq"].shape[:2]
        self._q = t["twist_dq"].transpose(0, 2, 1)                                # (M,8,B)
        self._heads = np.asarray(skeleton.heads, dtype=np.float64)
        self._axes = np.asarray(skeleton.frames, dtype=np.float64)[:, :, 1]        # twist axes (B,3)
        self._chain = t["chain"].reshape(self.M, B, 3, 4)
        self._swing = t["swing_chain"].reshape(self.M, B, 3, 4)
        self._terms = {}

    def _anchor_terms(self, a):
        """Cached ``(q (M,8,k), maps (M,3(k+1),4))`` of anchor a: its children's twist dual quaternions
        and the rows of M_a followed by those of S_c − M_a for each child c."""
        if a not in self._terms:
            kids = self.kids[a]
            chain = self._chain[:, a]
            maps = np.concatenate([chain[:, None], self._swing[:, kids] - chain[:, None]], axis=1)
            self._terms[a] = (np.ascontiguousarray(self._q[:, :, kids]),
                              np.ascontiguousarray(maps.reshape(self.M, -1, 4)))
        return self._terms[a]

    def columns(self, a, x, wt):
        """Candidates with anchor a: rest points ``x (3,n)``, twist weights ``wt (k,n)`` on ``kids[a]``.
        Returns ``C (M,3(k+1),n)``: rows 0:3 the posed position with swing weights 0 (base), rows
        3(j+1):3(j+2) the effect of swing weight 1 on ``kids[a][j]`` (column G_j).  Metres."""
        q, maps = self._anchor_terms(a)
        n = x.shape[1]
        x = np.asarray(x, np.float64)
        wt = np.asarray(wt, np.float64)
        if q.shape[2] == 0:
            return np.matmul(maps, np.concatenate([x, np.ones((1, n))]))
        vt = np.empty((self.M, 4, n))
        vt[:, 3] = 1
        if q.shape[2] == 1:
            c = self.kids[a][0]
            axis = self._axes[c]
            _twist_one(x, wt[0], self._heads[c], axis, q[:, 0, 0], q[:, 1:4, 0] @ axis, vt)
        else:
            _dq_apply_soa(_twist_blend(q, wt), x, vt)
        return np.matmul(maps, vt)

    def base_and_columns(self, x, anchor, twist, kids):
        """x (n,3), anchor (n,), twist (n,B) float, kids (n,K) children of the anchor (-1 padded).
        Returns ``base (M,n,3)`` (swing weights 0) and ``G (M,n,3,K)`` (column j: effect of swing weight 1
        on kids[:, j]; 0 for padding), float64 (the reference layout of the tests)."""
        n, K = kids.shape
        base = np.empty((self.M, n, 3))
        G = np.zeros((self.M, n, 3, K))
        for a, rows in _by_label(np.asarray(anchor)):
            ka = self.kids[a]
            C = self.columns(a, x[rows].T, twist[rows[:, None], ka[None, :]].T)
            C = C.reshape(self.M, len(ka) + 1, 3, len(rows))
            base[:, rows] = C[:, 0].transpose(0, 2, 1)
            G[:, rows, :, :len(ka)] = C[:, 1:].transpose(0, 3, 2, 1)
        return base, G


def _dot(a, b):
    """``Σ_m,i a b`` ``(n,)`` of two ``(M,3,n)`` arrays."""
    return np.einsum("min,min->n", a, b)


def _normal_equations(C, r):
    """``H = Σ_m,i G_k G_l`` ``(n,k,k)`` and ``b = Σ_m,i G_k r`` ``(n,k)`` (float64) for the swing columns
    of ``C (M,3(k+1),n)`` (:meth:`CandidateSkin.columns`) and residuals ``r (M,3,n)``."""
    k, n = C.shape[1] // 3 - 1, C.shape[2]
    G = [C[:, 3 * (j + 1):3 * (j + 2)] for j in range(k)]
    H = np.empty((n, k, k))
    b = np.empty((n, k))
    for i in range(k):
        b[:, i] = _dot(G[i], r)
        for j in range(i, k):
            H[:, i, j] = H[:, j, i] = _dot(G[i], G[j])
    return H, b


# ----------------------------------------------------------------------------- evaluation

class _State:
    """Posed vertices, Laplacian residuals and the per-vertex completion-of-square quantities.
    Stored vertex-major ``(V,M,3)`` (``Pv``, ``Rv``, ``Sv``) so one vertex set is one row block and the
    Laplacian products are single sparse × dense products; ``P`` and ``R`` are ``(M,V,3)`` views."""

    def __init__(self, model, poses, objective):
        self.obj = objective
        L = objective.L.tocsr()
        self.LT = L.T.tocsr()
        self.Lc = L.tocsc()
        self.colsq = np.asarray(L.multiply(L).sum(axis=0)).ravel()     # Σ_n L[n,v]²
        self.kappa = 1.0 + objective.alpha * self.colsq
        P = hybrid_skin(model, poses)
        self.Pv = np.ascontiguousarray(P.transpose(1, 0, 2))
        self.Rv = np.ascontiguousarray((objective.laplacian(P) - objective.scan_lap).transpose(1, 0, 2))
        self.Sv = np.ascontiguousarray(objective.scans.transpose(1, 0, 2))

    P = property(lambda self: self.Pv.transpose(1, 0, 2), doc="posed vertices (M,V,3) (view)")
    R = property(lambda self: self.Rv.transpose(1, 0, 2), doc="Laplacian residuals L p − L s (M,V,3) (view)")

    def targets(self, idx):
        """g ``(n,M,3)`` for vertices idx."""
        n, V = len(idx), len(self.Pv)
        LtR = (self.LT[idx] @ self.Rv.reshape(V, -1)).reshape(n, -1, 3)
        a = self.obj.alpha
        return (self.Sv[idx] - a * (LtR - self.colsq[idx, None, None] * self.Pv[idx])) \
            / self.kappa[idx, None, None]

    def update(self, idx, P_new):
        """Set the posed positions ``(n,M,3)`` of vertices idx; residual rows of their one-ring follow."""
        d = (P_new - self.Pv[idx]).reshape(len(idx), -1)
        self.Pv[idx] = P_new
        cols = self.Lc[:, idx].tocsr()
        rows = np.flatnonzero(np.diff(cols.indptr))
        R = self.Rv.reshape(len(self.Pv), -1)
        R[rows] += cols[rows] @ d


class _DataTargets:
    """A stand-in for :class:`_State` whose targets ignore the Laplacian term (κ = 1, g = the scan vertex):
    candidate evaluation then proposes each vertex's best data fit, independently of its neighbours."""

    def __init__(self, state):
        self.Pv = state.Pv
        self.kappa = np.ones_like(state.kappa)
        self.Sv = state.Sv

    def targets(self, idx):
        return self.Sv[idx]


def _screen(skin, x, g, kap, f_cur, v, a, tw):
    """Screening pass over all candidates: each one's exact swing weights (QP) and its gain.

    x ``(n,3)`` rest points and g ``(M,3,n)`` targets of the evaluated vertices, kap, f_cur ``(n,)``;
    candidates v (index into the n vertices), a ``(c,)``, tw ``(c,B)``.  Returns ``gain (c,)`` and
    ``swing (c,K)`` float32 on the slots of ``kids[a]``.  A candidate's Q is ``κ (‖r‖² + wᵀHw − 2bᵀw)``
    with r = g − base (the QP's own value), so no posed position is formed here."""
    gain = np.empty(len(v))
    W = np.zeros((len(v), skin.K), np.float32)
    for anchor, rows in _by_label(a, _block(skin.M)):
        kids = skin.kids[anchor]
        vr = v[rows]
        C = skin.columns(anchor, x[vr].T, tw[rows[:, None], kids[None, :]].T)
        r = np.take(g, vr, axis=2) - C[:, :3]      # take: C-contiguous (g[:, :, vr] is not, and slow)
        f = _dot(r, r)
        if len(kids):
            H, bvec = _normal_equations(C, r)
            w, fq = _qp_group(H, bvec)
            W[rows, :len(kids)] = w
            f += fq
        gain[rows] = f_cur[vr] - kap[vr] * f
    return gain, W


def _exact(skin, x, g, kap, f_cur, a, tw, W):
    """One candidate per vertex: posed ``p (n,M,3)`` and the exact gain ``f_cur − κ‖p − g‖²``
    ``(n,)``.  x ``(n,3)``, g ``(M,3,n)``, a ``(n,)``, tw ``(n,B)``, W ``(n,K)`` swing on kids[a]."""
    p = np.empty(g.shape)
    for anchor, rows in _by_label(a, _block(skin.M)):
        kids = skin.kids[anchor]
        C = skin.columns(anchor, x[rows].T, tw[rows[:, None], kids[None, :]].T)
        base = C[:, :3]
        for j in range(len(kids)):
            base = base + W[rows, j].astype(np.float64) * C[:, 3 * (j + 1):3 * (j + 2)]   # float32 as stored
        p[:, :, rows] = base
    d = p - g
    return f_cur - kap * _dot(d, d), p.transpose(2, 0, 1)


def _best_per_vertex(v, gain):
    """Index ``(r,)`` of the candidate with the largest gain of each vertex in ``v (c,)`` whose best gain
    is positive (ties: the earliest candidate)."""
    order = np.lexsort((-gain, v))
    first = order[np.r_[True, v[order][1:] != v[order][:-1]]]
    return first[gain[first] > 0]


def _swing_rows(skin, a, W):
    """Swing weights ``(r,B)`` float32 from the compact ``W (r,K)`` on the children of anchors ``a (r,)``."""
    sw = np.zeros((len(a), len(skin.kids)), np.float32)
    for anchor, rows in _by_label(a):
        kids = skin.kids[anchor]
        sw[rows[:, None], kids[None, :]] = W[rows, :len(kids)]
    return sw


def evaluate(model, skin, state, idx, steps=STEPS):
    """Best candidate of each vertex in idx: ``(gain (n,), anchor (n,), twist (n,B) f32, swing (n,B) f32,
    posed (n,M,3))``; gain 0 and the current state where nothing improves.  skin: :class:`CandidateSkin`.

    Candidates are screened from their normal equations (one skinning evaluation and one QP call per
    candidate anchor, :func:`_screen`) coarse-to-fine in the step: first every move with the smallest
    step of ``steps`` (and the moves without a step), then the larger steps only along the directions
    (:func:`candidates`) whose smallest step gains.  Each vertex's best is then posed with its
    float32-stored weights (:func:`_exact`) and taken only if that exact gain is positive, so the
    reported gains are exactly the changes of Q."""
    g = state.targets(idx)
    kap = state.kappa[idx]
    p_cur = state.Pv[idx]
    f_cur = kap * np.einsum("nmi,nmi->n", p_cur - g, p_cur - g)
    best = (np.zeros(len(idx)), model.anchor[idx].copy(), model.twist_weights[idx].copy(),
            model.swing_weights[idx].copy(), p_cur.copy())
    anchor, twist, parents = model.anchor[idx], model.twist_weights[idx], model.skeleton.parents
    smallest = min(steps)
    v, a, tw, way = _candidate_list(anchor, twist, parents, (smallest,))
    gT = np.ascontiguousarray(g.transpose(1, 2, 0))                           # (M,3,n)
    x = model.rest_vertices[idx]
    gain, W = _screen(skin, x, gT, kap, f_cur, v, a, tw)
    larger = tuple(d for d in steps if d > smallest)
    grow = np.flatnonzero((way >= 0) & (gain > 0))
    if larger and len(grow):
        v2, a2, tw2 = _widened(anchor, twist, parents, v[grow], way[grow], larger)
        gain2, W2 = _screen(skin, x, gT, kap, f_cur, v2, a2, tw2)
        v, a, tw = np.concatenate([v, v2]), np.concatenate([a, a2]), np.concatenate([tw, tw2])
        gain, W = np.concatenate([gain, gain2]), np.concatenate([W, W2])
    first = _best_per_vertex(v, gain)
    vf = v[first]
    gain, p = _exact(skin, x[vf], np.take(gT, vf, axis=2), kap[vf], f_cur[vf], a[first], tw[first], W[first])
    ok = gain > 0
    first, tv = first[ok], vf[ok]
    best[0][tv] = gain[ok]
    best[1][tv] = a[first]
    best[2][tv] = tw[first]
    best[3][tv] = _swing_rows(skin, a[first], W[first])
    best[4][tv] = p[ok]
    return best


def evaluate_parallel(model, skin, state, idx, steps=STEPS):
    """:func:`evaluate` with ``idx`` cut into one piece per solver thread (:mod:`solver.parallel`; pieces
    of at least ``PARALLEL_MIN_WORK`` vertex-scans): a vertex's evaluation does not depend on the others
    in idx, so the result is that of one call (to rounding: the batched products see other shapes)."""
    pieces = [idx[p] for p in parallel.split(len(idx), -(-PARALLEL_MIN_WORK // state.Pv.shape[1]))]
    if len(pieces) == 1:
        return evaluate(model, skin, state, idx, steps)
    parts = parallel.map_pieces(lambda part: evaluate(model, skin, state, part, steps), pieces)
    return tuple(np.concatenate(arrays) for arrays in zip(*parts))


# ----------------------------------------------------------------------------- active set and joint move

class _Tracker:
    """Which evaluations a state change invalidates.

    ``stale (V,)``: the vertex's data-only proposal (:func:`joint_move`) must be recomputed — it depends on
    the vertex's own anchor and weights only.  ``dirty (V,)``: the vertex's BCD evaluation may differ from
    its last one — its targets g depend on the posed positions of its two-ring (``ring2``, CSR pattern),
    its candidates on its own state; a vertex that is not dirty had no improving candidate last time and
    would have none now.  ``proposal``: the cached joint-move proposals."""

    def __init__(self, model, M, ring2=None):
        V = model.num_vertices
        self.ring2 = ring2
        self.dirty = np.ones(V, dtype=bool)
        self.stale = np.ones(V, dtype=bool)
        self.proposal = (np.zeros(V), np.empty(V, np.int32), np.empty_like(model.twist_weights),
                         np.empty_like(model.swing_weights), np.empty((V, M, 3)))

    def changed(self, idx):
        """Vertices idx changed state."""
        self.stale[idx] = True
        self.dirty[idx] = True                       # also when a vertex has no Laplacian row
        if self.ring2 is not None and len(idx):
            self.dirty[self.ring2[idx].indices] = True


def joint_move(model, skin, state, objective, Q, steps=STEPS, chunk=4000, tracker=None):
    """Jacobi proposal with exact acceptance: every vertex proposes its best *data-only* candidate; the
    proposals with the largest data gains (all, then the best half, then a quarter) are applied together
    if that lowers the exact Q (recomputed in full).  Neighbouring vertices moving together keep the
    Laplacian term small where single-vertex moves are penalised by it.  Returns the new Q (≤ Q).
    With a :class:`_Tracker`, only stale proposals are recomputed and the applied vertices are reported
    to it.  Where :func:`parallel.can_fork`, half of the stale proposals are computed in a forked child
    (they are independent of each other)."""
    if tracker is None:
        tracker = _Tracker(model, state.Pv.shape[1])
    proxy = _DataTargets(state)
    gain, *prop = tracker.proposal
    todo = np.flatnonzero(tracker.stale)

    def propose(part, evaluator):
        out = [evaluator(model, skin, proxy, part[c0:c0 + chunk], steps) for c0 in range(0, len(part), chunk)]
        return tuple(np.concatenate(x) for x in zip(*out)) if out else None

    if parallel.can_fork() and len(todo) * skin.M >= 2 * SPLIT_MIN_WORK:   # independent: data-only proposals
        parts = [todo[: len(todo) // 2], todo[len(todo) // 2:]]
        proposals = parallel.fork_map(lambda part: propose(part, evaluate), parts)
    else:
        parts, proposals = [todo], [propose(todo, evaluate_parallel)]
    for idx, found in zip(parts, proposals):
        if found is not None:
            gain[idx], prop[0][idx], prop[1][idx], prop[2][idx], prop[3][idx] = found
    tracker.stale[todo] = False
    movers = np.flatnonzero(gain > 0)
    movers = movers[np.argsort(-gain[movers], kind="stable")]
    for frac in (1.0, 0.5, 0.25):
        sel = movers[:int(np.ceil(frac * len(movers)))]
        if len(sel) == 0:
            break
        P_try = state.Pv.copy()
        P_try[sel] = prop[3][sel]
        Q_try = objective.value(P_try.transpose(1, 0, 2))
        if Q_try < Q:
            model.anchor[sel], model.twist_weights[sel], model.swing_weights[sel] = \
                prop[0][sel], prop[1][sel], prop[2][sel]
            state.update(sel, prop[3][sel])
            tracker.changed(sel)
            return Q_try
    return Q


def two_ring_colouring(ring2):
    """Greedy colouring of the vertices such that two vertices within two rings of each other never share
    a colour.  ring2: ``(V,V)`` CSR pattern of the two-ring (incl. the vertex).  Returns colours ``(V,)``."""
    V = ring2.shape[0]
    colour = np.full(V, -1, dtype=np.int64)
    indptr, indices = ring2.indptr, ring2.indices
    for v in range(V):
        used = colour[indices[indptr[v]:indptr[v + 1]]]
        used = used[used >= 0]
        if len(used) == 0:
            colour[v] = 0
            continue
        free = np.flatnonzero(np.bincount(used, minlength=used.max() + 2) == 0)
        colour[v] = free[0]
    return colour


def _sweep(model, skin, state, objective, graph, tracker, Q, steps=STEPS, jacobi=True, wins=None):
    """One sweep: the joint move (if ``jacobi``), then every colour class of ``graph`` (:class:`TwoRing`)
    in turn, evaluating only the class's dirty vertices (all of them when every vertex is dirty).  When
    the sweep is large enough, the mesh is cut into two halves more than two rings apart and the band
    between them (:meth:`TwoRing.halves`): the classes are visited on each half, the halves in parallel
    (:func:`_halves_in_parallel`), then on the band.  Updates model, state and tracker in place; returns
    ``(Q, moved)``: the new Q (the old one minus the exact gains applied) and whether the joint move was
    applied.  wins: optional ``(len(steps),)`` int array; each applied move that changes a twist weight
    without changing the anchor adds one at the step nearest to its largest change."""
    moved = False
    if jacobi:
        Q_joint = joint_move(model, skin, state, objective, Q, steps, tracker=tracker)
        moved, Q = Q_joint < Q, Q_joint
    wins = np.zeros(len(steps), dtype=np.int64) if wins is None else wins
    dirty = int(tracker.dirty.sum())
    split = None
    if parallel.can_fork() and dirty * skin.M >= SPLIT_MIN_WORK * len(graph.classes):
        split = graph.halves(tracker.dirty * _candidate_cost(skin, model.anchor))
    if split is None:
        return Q - _visit(model, skin, state, graph.classes, tracker, Q, steps, wins, evaluate_parallel), moved
    half_a, half_b, band = split
    gained = _halves_in_parallel(model, skin, state, graph, tracker, Q, steps, wins, half_a, half_b)
    gained += _visit(model, skin, state, _subset_classes(graph.ring2, band), tracker, Q, steps, wins,
                     evaluate_parallel)
    return Q - gained, moved


def _subset_classes(ring2, mask):
    """Colour classes of the vertices where ``mask (V,)`` is True alone (:func:`two_ring_colouring` of
    the two-ring pattern restricted to them): no two within two rings share a class, and the thin band of
    :meth:`TwoRing.halves` needs fewer classes, i.e. fewer evaluation calls, than the mesh's colouring
    cut down to it (game_engine: 10 instead of 14 for 515 band vertices)."""
    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return []
    colour = two_ring_colouring(ring2[idx][:, idx].tocsr())
    return [idx[colour == c] for c in range(colour.max() + 1)]


def _visit(model, skin, state, classes, tracker, Q, steps, wins, evaluator):
    """Evaluate and update the dirty vertices of each class in ``classes`` in turn with ``evaluator``
    (:func:`evaluate` or :func:`evaluate_parallel`); a move is applied if it gains more than
    ``MIN_GAIN · Q``.  Returns the sum of the applied (exact) gains."""
    gained = 0.0
    for idx in classes:
        idx = idx[tracker.dirty[idx]]
        if len(idx) == 0:
            continue
        gain, a, tw, sw, p = evaluator(model, skin, state, idx, steps)
        tracker.dirty[idx] = False
        ok = gain > MIN_GAIN * max(Q, 1e-300)
        if not ok.any():
            continue
        chosen = idx[ok]
        _count_steps(wins, steps, model.anchor[chosen] == a[ok], model.twist_weights[chosen], tw[ok])
        model.anchor[chosen] = a[ok]
        model.twist_weights[chosen] = tw[ok]
        model.swing_weights[chosen] = sw[ok]
        state.update(chosen, p[ok])
        tracker.changed(chosen)
        gained += float(gain[ok].sum())
    return gained


def _restrict(classes, mask):
    """The colour classes cut down to the vertices where ``mask (V,)`` is True (empty ones dropped)."""
    out = [idx[mask[idx]] for idx in classes]
    return [idx for idx in out if len(idx)]


def _candidate_cost(skin, anchor):
    """Relative cost ``(V,)`` of evaluating each vertex: ``(1 + k)²`` for an anchor with k children (about
    k candidate directions, each skinned with k + 1 columns)."""
    k = np.array([len(kids) for kids in skin.kids], dtype=np.float64)
    return (1.0 + k[anchor]) ** 2


def _halves_in_parallel(model, skin, state, graph, tracker, Q, steps, wins, half_a, half_b):
    """Visit the classes on ``half_a`` in a forked child (:class:`parallel.ForkedCall`) while this process
    visits them on ``half_b``, then copy the child's changes in.  The halves are more than two rings
    apart, so neither half's targets depend on the other's posed positions and their Laplacian residual
    rows are disjoint: the result is that of visiting half_a, then half_b, in one process (which is what
    happens where fork is unavailable or the child fails).  Returns the sum of both halves' gains."""
    in_a = np.zeros(len(model.anchor), dtype=bool)
    in_a[half_a] = True
    zone = np.unique(graph.ring2[half_a].indices)              # vertices whose flags half_a's moves can set
    rows = np.unique(graph.ring1[half_a].indices)              # residual rows half_a's moves change
    classes_a = _restrict(graph.classes, in_a)
    in_b = np.zeros_like(in_a)
    in_b[half_b] = True

    def visit_a():
        w = np.zeros_like(wins)
        gained = _visit(model, skin, state, classes_a, tracker, Q, steps, w, evaluate)
        return dict(gained=gained, wins=w, anchor=model.anchor[half_a], twist=model.twist_weights[half_a],
                    swing=model.swing_weights[half_a], P=state.Pv[half_a], R=state.Rv[rows],
                    dirty=tracker.dirty[zone], stale=tracker.stale[half_a])

    with parallel.ForkedCall(visit_a) as job:
        gained = _visit(model, skin, state, _restrict(graph.classes, in_b), tracker, Q, steps, wins, evaluate)
        try:
            out = job.result()
        except parallel.ForkFailed:
            out = visit_a()                              # this process has not touched half_a
    model.anchor[half_a], model.twist_weights[half_a], model.swing_weights[half_a] = \
        out["anchor"], out["twist"], out["swing"]
    state.Pv[half_a], state.Rv[rows] = out["P"], out["R"]
    own = in_a[zone]
    tracker.dirty[zone[own]] = out["dirty"][own]                   # half_a's vertices: as the child left them
    tracker.dirty[zone[~own]] |= out["dirty"][~own]                # band vertices: either side may mark them
    tracker.stale[half_a] = out["stale"]
    wins += out["wins"]
    return gained + out["gained"]


def _count_steps(wins, steps, same_anchor, old, new):
    """Add the moves ``old → new (n, B)`` with an unchanged anchor and a changed twist to ``wins``, at the
    step nearest to each move's largest weight change."""
    change = np.abs(new[same_anchor].astype(np.float64) - old[same_anchor]).max(axis=1)
    change = change[change > 1e-6]
    if len(change):
        near = np.abs(change[:, None] - np.asarray(steps)[None]).argmin(axis=1)
        wins += np.bincount(near, minlength=len(steps))


def _kept_steps(steps, wins):
    """The steps for the next sweep: those that at least ``STEP_MIN_SHARE`` of the counted moves used, and
    always the smallest (all of them when nothing was counted)."""
    total = wins.sum()
    if total == 0:
        return tuple(steps)
    keep = [d for d, w in zip(steps, wins) if w >= STEP_MIN_SHARE * total or d == min(steps)]
    return tuple(keep)


class TwoRing:
    """The vertex graph of the BCD for a Laplacian ``L (V,V)``: ``ring1`` / ``ring2`` (CSR patterns of the
    one- and two-ring, incl. the vertex), the colour ``classes`` of :func:`two_ring_colouring` (list of
    index arrays) and ``levels (V,)``: breadth-first distance in edges from a pseudo-peripheral vertex
    (-1 where unreachable), from which :meth:`halves` cuts the mesh.  It depends on the mesh only, so one
    learn_rig builds it once for all its :func:`optimise_weights` calls (0.3 s per build on MakeHuman's
    13,380 vertices)."""

    def __init__(self, L):
        A1 = (sp.csr_matrix(L) != 0).astype(np.float64).tocsr()
        self.ring1 = A1
        self.ring2 = (A1 @ A1).tocsr()
        colour = two_ring_colouring(self.ring2)
        self.classes = [np.flatnonzero(colour == c) for c in range(colour.max() + 1)]
        self.levels = _peripheral_levels(A1)

    def halves(self, work):
        """``(half_a, half_b, band)`` for per-vertex ``work (V,)`` (relative cost to evaluate), or None
        when no cut leaves both halves work.  half_a: the vertices
        of level < l, half_b: level ≥ l + 2, band (boolean mask ``(V,)``): levels l and l + 1 and the
        unreachable vertices; l balances the halves' work.  A vertex of half_a and one of half_b are at
        least three edges apart, i.e. outside each other's two-ring."""
        work = np.asarray(work, dtype=np.float64)
        if self.levels.max() < 3:
            return None
        reach = self.levels >= 0
        per_level = np.bincount(self.levels[reach], weights=work[reach])
        below = np.concatenate([[0.0], np.cumsum(per_level)])         # below[l]: work of levels < l
        l = np.arange(1, len(per_level) - 2)                         # half_a = levels < l, non-empty
        above = below[-1] - below[l + 2]                              # work of levels ≥ l + 2
        l = int(l[np.argmin(np.abs(below[l] - above))])
        if below[l] == 0 or below[-1] - below[l + 2] == 0:
            return None
        half_a = np.flatnonzero(reach & (self.levels < l))
        half_b = np.flatnonzero(self.levels >= l + 2)
        band = ~reach | (self.levels == l) | (self.levels == l + 1)
        return half_a, half_b, band


def _peripheral_levels(A1):
    """Breadth-first levels ``(V,)`` int (-1: unreachable) over the graph ``A1`` from a pseudo-peripheral
    vertex of the component of vertex 0: the farthest vertex from the farthest vertex from 0 (two
    passes), so that the levels run along the mesh's longest extent."""
    V = A1.shape[0]
    if V == 0:
        return np.zeros(0, dtype=np.int64)
    src = 0
    for _ in range(2):
        d = csgraph.shortest_path(A1, unweighted=True, indices=src, directed=False)
        src = int(np.argmax(np.where(np.isfinite(d), d, -1.0)))
    d = csgraph.shortest_path(A1, unweighted=True, indices=src, directed=False)
    return np.where(np.isfinite(d), d, -1).astype(np.int64)


def _setup(model, poses, objective, graph=None):
    """Copy of the model, :class:`_State`, :class:`CandidateSkin`, Q, the :class:`TwoRing` (built from
    the objective's Laplacian unless given) and a fresh :class:`_Tracker` (everything dirty)."""
    model = Model(model.rest_vertices, model.faces, model.skeleton, model.anchor.copy(),
                  model.twist_weights.copy(), model.swing_weights.copy())
    state = _State(model, poses, objective)
    graph = TwoRing(objective.L) if graph is None else graph
    return (model, state, CandidateSkin(model.skeleton, poses), objective.value(state.P), graph,
            _Tracker(model, len(poses), graph.ring2))


@single_blas_thread()
def optimise_weights(model, poses, objective, max_sweeps=20, steps=STEPS, rel_tol=1e-6, progress=None,
                     jacobi=True, active_set=True, graph=None, prune_steps=True):
    """Sampling-based BCD on twist (and exact swing) weights with anchors; rest mesh, skeleton and poses
    fixed.  Returns ``(model, log, jacobi)``: the updated model (new anchor / weight arrays), the
    objective after every sweep (strictly decreasing) and whether the joint move is still in use (False
    once it was rejected: a caller that optimises again passes that on, see the module docstring).

    A sweep visits the colour classes of :func:`two_ring_colouring` in turn: the vertices of one class
    have disjoint Laplacian rows, so each is evaluated with up-to-date targets and all improving ones are
    applied together with an exactly additive gain (a block = one colour class).  With ``active_set``
    only vertices whose own state or two-ring changed since their last evaluation are evaluated (the
    others would find nothing), and the joint move reuses the proposals of unchanged vertices; without
    it every sweep evaluates everything (same result, for checking).  Stops after ``max_sweeps`` or when
    a sweep gains less than ``rel_tol`` of Q.  graph: the mesh's :class:`TwoRing` (built if None).
    prune_steps: after each sweep only the steps δ that won at least ``STEP_MIN_SHARE`` of its twist
    moves are offered in the next (:func:`_kept_steps`; the smallest always), see the module docstring.
    Runs with numpy's BLAS on one thread (small products only: spinning BLAS threads just compete)."""
    model, state, skin, Q, graph, tracker = _setup(model, poses, objective, graph)
    log = []
    for sweep in range(max_sweeps):
        Q_start = Q
        if not active_set:
            tracker.dirty[:] = tracker.stale[:] = True
        wins = np.zeros(len(steps), dtype=np.int64)
        Q, moved = _sweep(model, skin, state, objective, graph, tracker, Q, steps, jacobi, wins)
        jacobi = jacobi and moved           # a rejected joint move is not tried again
        if prune_steps:
            steps = _kept_steps(steps, wins)
        if Q >= Q_start:
            break
        log.append(Q)
        if progress is not None:
            progress((sweep + 1) / max_sweeps, "skinning weights (block coordinate descent)", Q)
        if Q_start - Q < rel_tol * Q_start:
            break
    return model, log, jacobi
