"""One sweep of the weight step: the joint move, then every colour class in turn (dissertation
(model-adaptive mocap) §3.4 (A); the joint move, the halves in parallel and step pruning are ours, see
docs/learn_rig_solver.md).

Joint move: every vertex proposes its best data-only candidate and the proposals are applied together
only if the exactly recomputed Q decreases (a lone move is held back by its one-ring's Laplacian rows).
Classes: the dirty vertices of one class are evaluated against the current residuals and every
improving one takes its best candidate; Q decreases by exactly the sum of the applied gains.  Large
sweeps are cut into two halves more than two rings apart, one visited in a forked child, and the band
between them.  Step pruning: a step δ that won few of a sweep's twist moves is not offered in the next."""
import numpy as np

from ... import parallel
from .candidates import STEPS
from .colouring import restrict_classes, subset_classes
from .evaluation import evaluate, evaluate_parallel
from .state import DataTargets, Tracker

SPLIT_MIN_WORK = 10_000   # dirty vertex-scans per colour class below which a sweep is not cut into halves
                          # (each evaluate call has a fixed interpreter cost the second core must win back)
MIN_GAIN = 1e-15       # a move is applied only if it gains more than this fraction of Q
STEP_MIN_SHARE = 0.01  # a step δ is offered again in a call's next sweep if it won this share of the moves


def joint_move(model, skin, state, objective, Q, steps=STEPS, chunk=4000, tracker=None, tick=None):
    """Jacobi proposal with exact acceptance: every vertex proposes its best *data-only* candidate; the
    proposals with the largest data gains (all, then the best half, then a quarter) are applied together
    if that lowers the exact Q (recomputed in full).  Neighbouring vertices moving together keep the
    Laplacian term small where single-vertex moves are penalised by it.  Returns the new Q (≤ Q).
    With a :class:`Tracker`, only stale proposals are recomputed and the applied vertices are reported
    to it.  Where :func:`parallel.can_fork`, half of the stale proposals are computed in a forked child
    (they are independent of each other).  tick(fraction): called in this process after every chunk of
    its proposals and once the child's are in (see :func:`sweep`)."""
    if tracker is None:
        tracker = Tracker(model, state.Pv.shape[1])
    proxy = DataTargets(state)
    gain, *prop = tracker.proposal
    todo = np.flatnonzero(tracker.stale)

    def propose(part, evaluator, tick):
        out = []
        for c0 in range(0, len(part), chunk):
            out.append(evaluator(model, skin, proxy, part[c0:c0 + chunk], steps))
            if tick is not None:
                tick(min(c0 + chunk, len(part)) / len(part))
        return tuple(np.concatenate(x) for x in zip(*out)) if out else None

    if parallel.can_fork() and len(todo) * skin.M >= 2 * SPLIT_MIN_WORK:   # independent: data-only proposals
        parts = [todo[: len(todo) // 2], todo[len(todo) // 2:]]
        with parallel.ForkedCall(lambda: propose(parts[1], evaluate, None)) as job:   # the child: no ticks
            mine = propose(parts[0], evaluate, _span(tick, 0.0, 0.5))
            try:
                theirs = job.result()
            except parallel.ForkFailed:
                theirs = propose(parts[1], evaluate, None)
        proposals = [mine, theirs]
    else:
        parts, proposals = [todo], [propose(todo, evaluate_parallel, _span(tick, 0.0, 0.8))]
    if tick is not None:
        tick(0.8)
    for idx, found in zip(parts, proposals):
        if found is not None:
            gain[idx], prop[0][idx], prop[1][idx], prop[2][idx], prop[3][idx] = found
    tracker.stale[todo] = False
    movers = np.flatnonzero(gain > 0)
    movers = movers[np.argsort(-gain[movers], kind="stable")]
    for tried, frac in enumerate((1.0, 0.5, 0.25)):
        sel = movers[:int(np.ceil(frac * len(movers)))]
        if len(sel) == 0:
            break
        P_try = state.Pv.copy()
        P_try[sel] = prop[3][sel]
        Q_try = objective.value(P_try.transpose(1, 0, 2))
        if tick is not None:
            tick(0.8 + 0.2 * (tried + 1) / 3)
        if Q_try < Q:
            model.anchor[sel], model.twist_weights[sel], model.swing_weights[sel] = \
                prop[0][sel], prop[1][sel], prop[2][sel]
            state.update(sel, prop[3][sel])
            tracker.changed(sel)
            return Q_try
    return Q


def sweep(model, skin, state, objective, graph, tracker, Q, steps=STEPS, jacobi=True, wins=None, tick=None):
    """One sweep: the joint move (if ``jacobi``), then every colour class of ``graph`` (:class:`TwoRing`)
    in turn, evaluating only the class's dirty vertices (all of them when every vertex is dirty).  When
    the sweep is large enough, the mesh is cut into two halves more than two rings apart and the band
    between them (:meth:`TwoRing.halves`): the classes are visited on each half, the halves in parallel
    (:func:`_halves_in_parallel`), then on the band.  Updates model, state and tracker in place; returns
    ``(Q, moved)``: the new Q (the old one minus the exact gains applied) and whether the joint move was
    applied.  wins: optional ``(len(steps),)`` int array; each applied move that changes a twist weight
    without changing the anchor adds one at the step nearest to its largest change.
    tick(fraction of the sweep): called by this process only, after the joint move's chunks and every
    colour class it evaluates (the forked half's classes: once, when its result is in); it may raise
    (``Cancelled``) and then the model, state and tracker are partly updated: callers work on copies."""
    moved = False
    start = 0.2 if jacobi else 0.0                 # the share of the sweep's ticks given to the joint move
    if jacobi:
        Q_joint = joint_move(model, skin, state, objective, Q, steps, tracker=tracker, tick=_span(tick, 0.0, start))
        moved, Q = Q_joint < Q, Q_joint
    wins = np.zeros(len(steps), dtype=np.int64) if wins is None else wins
    dirty = int(tracker.dirty.sum())
    split = None
    if parallel.can_fork() and dirty * skin.M >= SPLIT_MIN_WORK * len(graph.classes):
        split = graph.halves(tracker.dirty * _candidate_cost(skin, model.anchor))
    if split is None:
        return Q - _visit(model, skin, state, graph.classes, tracker, Q, steps, wins, evaluate_parallel,
                          _span(tick, start, 1.0)), moved
    half_a, half_b, band = split
    middle = start + 0.8 * (1.0 - start)
    gained = _halves_in_parallel(model, skin, state, graph, tracker, Q, steps, wins, half_a, half_b,
                                 _span(tick, start, middle))
    gained += _visit(model, skin, state, subset_classes(graph.ring2, band), tracker, Q, steps, wins,
                     evaluate_parallel, _span(tick, middle, 1.0))
    return Q - gained, moved


def _span(tick, lo, hi):
    """``tick`` with its fraction mapped into [lo, hi] (None stays None)."""
    return None if tick is None else (lambda f: tick(lo + (hi - lo) * f))


def _visit(model, skin, state, classes, tracker, Q, steps, wins, evaluator, tick=None):
    """Evaluate and update the dirty vertices of each class in ``classes`` in turn with ``evaluator``
    (:func:`evaluate` or :func:`evaluate_parallel`); a move is applied if it gains more than
    ``MIN_GAIN · Q``.  ``tick(fraction of the classes done)`` before each evaluated class but the first.
    Returns the sum of the applied (exact) gains."""
    gained = 0.0
    for number, idx in enumerate(classes):
        idx = idx[tracker.dirty[idx]]
        if len(idx) == 0:
            continue
        if tick is not None and number:
            tick(number / len(classes))
        gain, a, tw, sw, p = evaluator(model, skin, state, idx, steps)
        tracker.dirty[idx] = False
        ok = gain > MIN_GAIN * max(Q, 1e-300)
        if not ok.any():
            continue
        chosen = idx[ok]
        count_steps(wins, steps, model.anchor[chosen] == a[ok], model.twist_weights[chosen], tw[ok])
        model.anchor[chosen] = a[ok]
        model.twist_weights[chosen] = tw[ok]
        model.swing_weights[chosen] = sw[ok]
        state.update(chosen, p[ok])
        tracker.changed(chosen)
        gained += float(gain[ok].sum())
    return gained


def _candidate_cost(skin, anchor):
    """Relative cost ``(V,)`` of evaluating each vertex: ``(1 + k)²`` for an anchor with k children (about
    k candidate directions, each skinned with k + 1 columns)."""
    k = np.array([len(kids) for kids in skin.kids], dtype=np.float64)
    return (1.0 + k[anchor]) ** 2


def _halves_in_parallel(model, skin, state, graph, tracker, Q, steps, wins, half_a, half_b, tick=None):
    """Visit the classes on ``half_a`` in a forked child (:class:`parallel.ForkedCall`) while this process
    visits them on ``half_b``, then copy the child's changes in.  The halves are more than two rings
    apart, so neither half's targets depend on the other's posed positions and their Laplacian residual
    rows are disjoint: the result is that of visiting half_a, then half_b, in one process (which is what
    happens where fork is unavailable or the child fails).  Returns the sum of both halves' gains.
    tick: this process's classes in [0, 0.9], then 1 when the child's result is in (the child cannot
    report); raising in it kills the child (:class:`parallel.ForkedCall`)."""
    in_a = np.zeros(len(model.anchor), dtype=bool)
    in_a[half_a] = True
    zone = np.unique(graph.ring2[half_a].indices)              # vertices whose flags half_a's moves can set
    rows = np.unique(graph.ring1[half_a].indices)              # residual rows half_a's moves change
    classes_a = restrict_classes(graph.classes, in_a)
    in_b = np.zeros_like(in_a)
    in_b[half_b] = True

    def visit_a():
        w = np.zeros_like(wins)
        gained = _visit(model, skin, state, classes_a, tracker, Q, steps, w, evaluate)
        return dict(gained=gained, wins=w, anchor=model.anchor[half_a], twist=model.twist_weights[half_a],
                    swing=model.swing_weights[half_a], P=state.Pv[half_a], R=state.Rv[rows],
                    dirty=tracker.dirty[zone], stale=tracker.stale[half_a])

    with parallel.ForkedCall(visit_a) as job:
        gained = _visit(model, skin, state, restrict_classes(graph.classes, in_b), tracker, Q, steps, wins, evaluate,
                        _span(tick, 0.0, 0.9))
        try:
            out = job.result()
        except parallel.ForkFailed:
            out = visit_a()                              # this process has not touched half_a
    if tick is not None:
        tick(1.0)
    model.anchor[half_a], model.twist_weights[half_a], model.swing_weights[half_a] = \
        out["anchor"], out["twist"], out["swing"]
    state.Pv[half_a], state.Rv[rows] = out["P"], out["R"]
    own = in_a[zone]
    tracker.dirty[zone[own]] = out["dirty"][own]                   # half_a's vertices: as the child left them
    tracker.dirty[zone[~own]] |= out["dirty"][~own]                # band vertices: either side may mark them
    tracker.stale[half_a] = out["stale"]
    wins += out["wins"]
    return gained + out["gained"]


def count_steps(wins, steps, same_anchor, old, new):
    """Add the moves ``old → new (n, B)`` with an unchanged anchor and a changed twist to ``wins``, at the
    step nearest to each move's largest weight change."""
    change = np.abs(new[same_anchor].astype(np.float64) - old[same_anchor]).max(axis=1)
    change = change[change > 1e-6]
    if len(change):
        near = np.abs(change[:, None] - np.asarray(steps)[None]).argmin(axis=1)
        wins += np.bincount(near, minlength=len(steps))


def kept_steps(steps, wins):
    """The steps for the next sweep: those that at least ``STEP_MIN_SHARE`` of the counted moves used, and
    always the smallest (all of them when nothing was counted)."""
    total = wins.sum()
    if total == 0:
        return tuple(steps)
    keep = [d for d, w in zip(steps, wins) if w >= STEP_MIN_SHARE * total or d == min(steps)]
    return tuple(keep)

