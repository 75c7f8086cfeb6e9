"""Each vertex's best candidate in the weight step, with its exact gain.

Candidates (:mod:`.candidates`) are grouped by candidate anchor and skinned together (:mod:`.skin`).
Screening ranks them by ``κ (‖r‖² + wᵀHw − 2bᵀw)``, r = g − base, from the normal equations and the
swing QP's own value (:mod:`.qp`), without forming posed positions; only each vertex's best is then
posed with its float32-stored weights and its gain recomputed as ``f_cur − κ‖p − g‖²``, so the booked
gains are exactly the changes of Q (:mod:`.state` for g and κ).  Steps are offered coarse-to-fine: the
larger steps only along the directions whose smallest step gains (see docs/learn_rig_solver.md)."""
import numpy as np

from ... import parallel
from .candidates import STEPS, by_label, candidate_list, widened_candidates
from .qp import qp_group
from .skin import dot, normal_equations

PARALLEL_MIN_WORK = 60_000    # vertex-scans per thread of one evaluation (less: one thread; smaller pieces
                              # lose more to the interpreter lock than the second thread gains)
BLOCK = 2 ** 16        # scan-candidates (M · candidates) per skinning block: each (M, n) temporary is at
                       # most 512 KiB and stays in cache; 2184 candidates at M = 30, 163 at M = 400


def _block(M):
    """Candidates per skinning block for M scans (see ``BLOCK``)."""
    return max(64, BLOCK // max(M, 1))


def _screen(skin, x, g, kap, f_cur, v, a, tw):
    """Screening pass over all candidates: each one's exact swing weights (QP) and its gain.

    x ``(n,3)`` rest points and g ``(M,3,n)`` targets of the evaluated vertices, kap, f_cur ``(n,)``;
    candidates v (index into the n vertices), a ``(c,)``, tw ``(c,B)``.  Returns ``gain (c,)`` and
    ``swing (c,K)`` float32 on the slots of ``kids[a]``.  A candidate's Q is ``κ (‖r‖² + wᵀHw − 2bᵀw)``
    with r = g − base (the QP's own value), so no posed position is formed here."""
    gain = np.empty(len(v))
    W = np.zeros((len(v), skin.K), np.float32)
    for anchor, rows in by_label(a, _block(skin.M)):
        kids = skin.kids[anchor]
        vr = v[rows]
        C = skin.columns(anchor, x[vr].T, tw[rows[:, None], kids[None, :]].T)
        r = np.take(g, vr, axis=2) - C[:, :3]      # take: C-contiguous (g[:, :, vr] is not, and slow)
        f = dot(r, r)
        if len(kids):
            H, bvec = normal_equations(C, r)
            w, fq = qp_group(H, bvec)
            W[rows, :len(kids)] = w
            f += fq
        gain[rows] = f_cur[vr] - kap[vr] * f
    return gain, W


def _exact(skin, x, g, kap, f_cur, a, tw, W):
    """One candidate per vertex: posed ``p (n,M,3)`` and the exact gain ``f_cur − κ‖p − g‖²``
    ``(n,)``.  x ``(n,3)``, g ``(M,3,n)``, a ``(n,)``, tw ``(n,B)``, W ``(n,K)`` swing on kids[a]."""
    p = np.empty(g.shape)
    for anchor, rows in by_label(a, _block(skin.M)):
        kids = skin.kids[anchor]
        C = skin.columns(anchor, x[rows].T, tw[rows[:, None], kids[None, :]].T)
        base = C[:, :3]
        for j in range(len(kids)):
            base = base + W[rows, j].astype(np.float64) * C[:, 3 * (j + 1):3 * (j + 2)]   # float32 as stored
        p[:, :, rows] = base
    d = p - g
    return f_cur - kap * dot(d, d), p.transpose(2, 0, 1)


def _best_per_vertex(v, gain):
    """Index ``(r,)`` of the candidate with the largest gain of each vertex in ``v (c,)`` whose best gain
    is positive (ties: the earliest candidate)."""
    order = np.lexsort((-gain, v))
    first = order[np.r_[True, v[order][1:] != v[order][:-1]]]
    return first[gain[first] > 0]


def _swing_rows(skin, a, W):
    """Swing weights ``(r,B)`` float32 from the compact ``W (r,K)`` on the children of anchors ``a (r,)``."""
    sw = np.zeros((len(a), len(skin.kids)), np.float32)
    for anchor, rows in by_label(a):
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
    v, a, tw, way = candidate_list(anchor, twist, parents, (smallest,))
    gT = np.ascontiguousarray(g.transpose(1, 2, 0))                           # (M,3,n)
    x = model.rest_vertices[idx]
    gain, W = _screen(skin, x, gT, kap, f_cur, v, a, tw)
    larger = tuple(d for d in steps if d > smallest)
    grow = np.flatnonzero((way >= 0) & (gain > 0))
    if larger and len(grow):
        v2, a2, tw2 = widened_candidates(anchor, twist, parents, v[grow], way[grow], larger)
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

