"""The weight step of learn_rig: twist and swing weights by sampling-based block coordinate descent
with anchors (dissertation (model-adaptive mocap) §3.4 (A), anchors §1.5).  Rest mesh, skeleton and poses
stay fixed; Q is the rig objective of :mod:`solver.learn.objective`."""
import numpy as np

from ...parallel import single_blas_thread
from ...rig.model import Model
from .candidates import STEPS
from .colouring import TwoRing
from .skin import CandidateSkin
from .state import State, Tracker
from .sweeps import kept_steps, sweep

STAGE = "skinning weights (block coordinate descent)"


def _setup(model, poses, objective, graph=None):
    """Copy of the model, :class:`State`, :class:`CandidateSkin`, Q, the :class:`TwoRing` (built from
    the objective's Laplacian unless given) and a fresh :class:`Tracker` (everything dirty)."""
    model = Model(model.rest_vertices, model.faces, model.skeleton, model.anchor.copy(),
                  model.twist_weights.copy(), model.swing_weights.copy())
    state = State(model, poses, objective)
    graph = TwoRing(objective.L) if graph is None else graph
    return (model, state, CandidateSkin(model.skeleton, poses), objective.value(state.P), graph,
            Tracker(model, len(poses), graph.ring2))


@single_blas_thread()
def optimise_weights(model, poses, objective, max_sweeps=20, steps=STEPS, rel_tol=1e-6, progress=None,
                     jacobi=True, active_set=True, graph=None, prune_steps=True):
    """Sampling-based BCD on twist (and exact swing) weights with anchors; rest mesh, skeleton and poses
    fixed.  Returns ``(model, log, jacobi)``: the updated model (new anchor / weight arrays), the
    objective after every sweep (strictly decreasing) and whether the joint move is still in use (False
    once it was rejected: a caller that optimises again passes that on; late in the alternation it
    never gains).

    A sweep visits the colour classes of :func:`two_ring_colouring` in turn: the vertices of one class
    have disjoint Laplacian rows, so each is evaluated with up-to-date targets and all improving ones are
    applied together with an exactly additive gain (a block = one colour class).  With ``active_set``
    only vertices whose own state or two-ring changed since their last evaluation are evaluated (the
    others would find nothing), and the joint move reuses the proposals of unchanged vertices; without
    it every sweep evaluates everything (same result, for checking).  Stops after ``max_sweeps`` or when
    a sweep gains less than ``rel_tol`` of Q.  graph: the mesh's :class:`TwoRing` (built if None).
    prune_steps: after each sweep only the steps δ that won at least ``STEP_MIN_SHARE`` of its twist
    moves are offered in the next (:func:`kept_steps`; the smallest always).
    progress(fraction, stage, objective): after every sweep with its Q, and within a sweep (colour
    classes, chunks of the joint move) without one; may raise ``Cancelled`` (the caller's model is
    untouched: the sweeps work on a copy).
    Runs with numpy's BLAS on one thread (small products only: spinning BLAS threads just compete)."""
    model, state, skin, Q, graph, tracker = _setup(model, poses, objective, graph)
    log = []
    for i in range(max_sweeps):
        Q_start = Q
        if not active_set:
            tracker.dirty[:] = tracker.stale[:] = True
        wins = np.zeros(len(steps), dtype=np.int64)
        tick = None if progress is None else (
            lambda f, i=i: progress((i + f) / max_sweeps, STAGE, None))
        Q, moved = sweep(model, skin, state, objective, graph, tracker, Q, steps, jacobi, wins, tick)
        jacobi = jacobi and moved           # a rejected joint move is not tried again
        if prune_steps:
            steps = kept_steps(steps, wins)
        if Q >= Q_start:
            break
        log.append(Q)
        if progress is not None:
            progress((i + 1) / max_sweeps, STAGE, Q)
        if Q_start - Q < rel_tol * Q_start:
            break
    return model, log, jacobi

