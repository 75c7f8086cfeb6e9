"""Candidate evaluation (weights.evaluation): coarse-to-fine steps against screening every candidate."""
import numpy as np

from articula.solver.learn.weights.candidates import candidate_list
from articula.solver.learn.weights.evaluation import _screen, evaluate
from articula.solver.learn.weights.optimise import _setup
from articula.solver.learn.weights.sweeps import sweep

from .problems import noisy_problem


def _screen_all(model, skin, state, idx, steps):
    """Reference for evaluate's screening: every candidate of every step, each vertex's best screened
    gain ``(n,)`` (0 where none gains)."""
    g = state.targets(idx)
    kap = state.kappa[idx]
    d = state.Pv[idx] - g
    f_cur = kap * np.einsum("nmi,nmi->n", d, d)
    v, a, tw, _ = candidate_list(model.anchor[idx], model.twist_weights[idx], model.skeleton.parents, steps)
    gain, _ = _screen(skin, model.rest_vertices[idx], np.ascontiguousarray(g.transpose(1, 2, 0)), kap, f_cur,
                      v, a, tw)
    best = np.zeros(len(idx))
    np.maximum.at(best, v, gain)
    return best


def test_coarse_to_fine_steps_lie_between_smallest_step_and_all_steps():
    """evaluate (smallest step everywhere, larger steps along the gaining directions) gains at least what
    the smallest step alone gains, more on some vertices (the widening is used), at most what every step
    gains (screened, brute force over all candidates) and on most vertices exactly that."""
    start, poses, obj = noisy_problem()
    model, state, skin, Q, graph, tracker = _setup(start, poses, obj)
    for _ in range(2):                                    # interior twist weights: every move kind occurs
        Q, _ = sweep(model, skin, state, obj, graph, tracker, Q)
    idx = np.arange(model.num_vertices)
    steps = (0.2, 0.1, 0.05, 0.02)
    coarse = evaluate(model, skin, state, idx, steps)[0]
    tol = 1e-8 * Q          # exact gains (float32-stored weights) vs screened ones: ~3e-5 of a gain apart
    small = _screen_all(model, skin, state, idx, (0.02,))
    assert np.all(coarse >= small - tol) and (coarse > small + tol).any()
    full = _screen_all(model, skin, state, idx, steps)
    assert np.all(coarse <= full + tol)
    assert np.mean(np.abs(coarse - full) <= tol) > 0.9
