"""Twist-weight candidates of the weight step (dissertation (model-adaptive mocap) §3.4 (A), anchors §1.5).

Each vertex has an anchor part a and twist weights on the children of a.  Its candidates, for each step
δ of ``STEPS``: stay (only the swing weights are re-solved); slide along the chain, ``w_c ± δ`` for a child
c (clipped to [0, 1], sum ≤ 1; the neutral remainder absorbs the change); at forks, move δ from one child
to another; backward past the anchor (only without twist weight): anchor ← parent, weight 1 − δ (and
exactly 1: the same transform) on the old anchor's joint; forward (only where one twist weight is 1):
anchor ← that child with all weights 0 (the same transform), optionally δ on one of its children."""
import itertools

import numpy as np

STEPS = (0.2, 0.1, 0.05, 0.02)


def children_table(parents):
    """``(B, K)`` int table of each bone's children (ascending), padded with -1; K ≥ 1 is the most
    children of any bone.  parents ``(B,)`` (-1 for the root)."""
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
    per candidate slot (the moves of the module docstring).  direction (int) names the move without its
    step δ — the same for ``w_c + 0.02`` and ``w_c + 0.2`` — and is −1 for the moves that have no step
    (stay, the re-expressions backward and forward at weight 1); :func:`evaluate` widens the steps along
    the directions whose smallest step gains."""
    n = len(twist)
    kids = children_table(parents)
    rows = np.arange(n)
    ck = kids[anchor]                                            # (n,K) children of the anchor
    cur = np.where(ck >= 0, twist[rows[:, None], np.maximum(ck, 0)], 0.0)
    yield anchor, twist, np.ones(n, dtype=bool), -1              # stay: swing only
    direction = itertools.count()
    yield from _slides(anchor, twist, ck, cur, steps, direction)
    yield from _fork_moves(anchor, twist, ck, cur, steps, direction)
    yield from _backward(anchor, twist, parents, cur, steps, direction)
    yield from _forward(anchor, twist, kids, ck, cur, steps, direction)


def _slides(anchor, twist, ck, cur, steps, direction):
    """``w_c ± δ`` on each child slot of ``ck (n,K)`` (current weights ``cur (n,K)``), clipped to [0, 1],
    valid where it changes the weight and keeps the sum ≤ 1.  ``direction``: the shared move counter."""
    rows = np.arange(len(twist))
    total = cur.sum(axis=1)
    for j in range(ck.shape[1]):
        c = ck[:, j]
        for sign in (1.0, -1.0):
            way = next(direction)
            for d in steps:
                new = np.clip(cur[:, j] + sign * d, 0.0, 1.0)
                valid = (c >= 0) & (new != cur[:, j]) & (total - cur[:, j] + new <= 1.0 + 1e-9)
                tw = twist.copy()
                tw[rows[valid], c[valid]] = new[valid]
                yield anchor, tw, valid, way


def _fork_moves(anchor, twist, ck, cur, steps, direction):
    """Move up to δ of twist weight from one child slot of ``ck (n,K)`` to another (ordered pairs)."""
    rows = np.arange(len(twist))
    for j, j2 in itertools.permutations(range(ck.shape[1]), 2):
        c, c2 = ck[:, j], ck[:, j2]
        way = next(direction)
        for d in steps:
            amount = np.minimum(d, np.minimum(cur[:, j], 1.0 - cur[:, j2]))
            valid = (c >= 0) & (c2 >= 0) & (amount > 0)
            tw = twist.copy()
            tw[rows[valid], c[valid]] -= amount[valid]
            tw[rows[valid], c2[valid]] += amount[valid]
            yield anchor, tw, valid, way


def _backward(anchor, twist, parents, cur, steps, direction):
    """Vertices without twist weight (``cur (n,K)`` all 0) and a parent anchor: anchor ← parent with
    weight 1 (the same transform, stepless) and 1 − δ on the old anchor's joint."""
    rows = np.arange(len(twist))
    par = parents[anchor]
    back_ok = (par >= 0) & (cur.sum(axis=1) == 0)
    way = next(direction)
    for d in (0.0,) + tuple(steps):
        tw = np.zeros_like(twist)
        tw[rows[back_ok], anchor[back_ok]] = 1.0 - d
        yield np.where(back_ok, par, anchor), tw, back_ok.copy(), way if d else -1


def _forward(anchor, twist, kids, ck, cur, steps, direction):
    """Vertices with a twist weight of 1: anchor ← that child with all weights 0 (the same transform,
    stepless), then δ on each of its children (``kids (B,K)``: :func:`children_table`)."""
    rows = np.arange(len(twist))
    full = cur >= 1.0 - 1e-6
    fwd_ok = full.any(axis=1)
    target = np.where(fwd_ok, ck[rows, np.argmax(full, axis=1)], anchor)
    yield target, np.zeros_like(twist), fwd_ok.copy(), -1
    gk = kids[target]
    for j in range(ck.shape[1]):
        way = next(direction)
        for d in steps:
            valid = fwd_ok & (gk[:, j] >= 0)
            tw = np.zeros_like(twist)
            tw[rows[valid], gk[valid, j]] = d
            yield target, tw, valid, way


# ----------------------------------------------------------------------------- candidate list

def candidate_list(anchor, twist, parents, steps=STEPS):
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


def widened_candidates(anchor, twist, parents, v, way, steps):
    """The candidates with the larger ``steps`` along the directions ``way (r,)`` of the vertices
    ``v (r,)`` (indices into ``anchor (n,)``, ``twist (n,B)``; a vertex may appear once per direction).
    Returns ``(v, anchor, twist f32)`` of :func:`candidate_list`'s layout."""
    rv, ra, rt, rd = candidate_list(anchor[v], twist[v], parents, steps)
    keep = rd == way[rv]
    return v[rv[keep]], ra[keep], rt[keep]


def by_label(labels, block=None):
    """``(label, rows)`` for each distinct value of ``labels (c,)`` (rows ascending), in pieces of at most
    ``block`` rows when given."""
    order = np.argsort(labels, kind="stable")
    cuts = np.flatnonzero(np.diff(labels[order])) + 1
    for rows in np.split(order, cuts):
        step = block or max(len(rows), 1)
        for s in range(0, len(rows), step):
            yield int(labels[rows[0]]), rows[s:s + step]

