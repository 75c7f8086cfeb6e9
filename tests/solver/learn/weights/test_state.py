"""The weight step's state and active set (weights.state) against a state rebuilt from scratch."""
import numpy as np

from articula.solver.learn.weights.evaluation import evaluate
from articula.solver.learn.weights.optimise import _setup
from articula.solver.learn.weights.state import DataTargets, State
from articula.solver.learn.weights.sweeps import MIN_GAIN, sweep

from .problems import noisy_problem


def test_tracker_skips_only_vertices_without_improving_candidates():
    """After some sweeps, against a state rebuilt from scratch (hybrid_skin of the model): every vertex
    the tracker holds clean has no candidate gaining more than the acceptance floor, every cached
    joint-move proposal equals a fresh data-only evaluation, and the running Q is the recomputed Q."""
    start, poses, obj = noisy_problem()
    model, state, skin, Q, graph, tracker = _setup(start, poses, obj)
    for _ in range(3):
        Q, _ = sweep(model, skin, state, obj, graph, tracker, Q, steps=(0.2, 0.05))
    fresh = State(model, poses, obj)
    assert np.isclose(obj.value(fresh.P), Q, rtol=1e-9, atol=0)
    assert np.allclose(fresh.R, state.R, atol=1e-12) and np.allclose(fresh.P, state.P, atol=1e-12)
    clean = np.flatnonzero(~tracker.dirty)
    assert 0 < len(clean) < model.num_vertices
    gain = evaluate(model, skin, fresh, clean, steps=(0.2, 0.05))[0]
    assert gain.max() <= MIN_GAIN * Q + 1e-12 * Q
    dirty = np.flatnonzero(tracker.dirty)
    assert (evaluate(model, skin, fresh, dirty, steps=(0.2, 0.05))[0] > MIN_GAIN * Q).any()   # not vacuous
    cached = np.flatnonzero(~tracker.stale)
    g, *_, p = evaluate(model, skin, DataTargets(fresh), cached, steps=(0.2, 0.05))
    assert np.allclose(tracker.proposal[0][cached], g, rtol=1e-9, atol=1e-15)
    moving = cached[g > 0]
    assert np.allclose(tracker.proposal[4][moving], p[g > 0], atol=1e-12)
