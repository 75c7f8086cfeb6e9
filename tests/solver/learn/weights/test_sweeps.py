"""Sweeps (weights.sweeps): the joint move, step pruning, halves in a forked child."""
import numpy as np

from articula.solver import parallel
from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.learn.weights import sweeps
from articula.solver.learn.weights.optimise import optimise_weights
from articula.solver.learn.weights.skin import CandidateSkin
from articula.solver.learn.weights.state import State
from articula.solver.learn.weights.sweeps import STEP_MIN_SHARE, count_steps, joint_move, kept_steps

from articula.sample_scenes.tube_scans import hybrid_truth
from .problems import binary_start, noisy_problem


def test_joint_move_never_increases_q_and_reports_it_exactly():
    model, poses, scans = hybrid_truth(4)
    rng = np.random.default_rng(5)
    noisy = scans + 0.002 * rng.normal(size=scans.shape)
    obj = RigObjective(noisy, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    m = binary_start(model)
    state = State(m, poses, obj)
    Q0 = obj.value(state.P)
    Q1 = joint_move(m, CandidateSkin(m.skeleton, poses), state, obj, Q0)
    assert Q1 < Q0
    assert np.isclose(obj.value(hybrid_skin(m, poses)), Q1, rtol=1e-12)      # model and state agree
    assert np.allclose(state.R, obj.laplacian(state.P) - obj.scan_lap, atol=1e-12)
    m.validate()


def test_step_pruning_counts_wins_and_keeps_the_smallest_step():
    steps = (0.2, 0.1, 0.05, 0.02)
    wins = np.zeros(4, dtype=np.int64)
    old = np.zeros((6, 3), dtype=np.float32)
    new = old.copy()
    new[0, 1], new[1, 1], new[2, 2], new[3, 0] = 0.02, 0.0199, 0.1, 0.2     # row 4: swing only, row 5 moved anchor
    new[5, 1] = 0.05
    count_steps(wins, steps, np.array([True] * 5 + [False]), old, new)
    assert wins.tolist() == [1, 1, 0, 2]
    assert kept_steps(steps, wins) == (0.2, 0.1, 0.02)
    assert kept_steps(steps, np.array([0, 0, 0, 0])) == steps
    many = np.array([0, 0, int(STEP_MIN_SHARE * 1000) - 1, 1000])
    assert kept_steps(steps, many) == (0.02,)


def test_split_sweeps_are_exact_and_the_same_with_or_without_fork(monkeypatch):
    """With every sweep cut into halves (SPLIT_MIN_WORK 0): the halves run in a forked child and here,
    or both here, with the same Q log and weights; the log is strictly decreasing and ends at the
    recomputed Q; the final Q is within 1 % of the unsplit BCD's (another visiting order), which is
    what runs where fork is unavailable."""
    start, poses, obj = noisy_problem()
    unsplit, log_unsplit, _ = optimise_weights(start, poses, obj, max_sweeps=3)
    monkeypatch.setattr(sweeps, "SPLIT_MIN_WORK", 0)
    calls = []
    real = sweeps._halves_in_parallel
    monkeypatch.setattr(sweeps, "_halves_in_parallel", lambda *a: calls.append(1) or real(*a))
    class InProcess(parallel.ForkedCall):                  # the split visit without the child
        def __init__(self, fn):
            self.fn, self.pid, self.fd = fn, None, None
    with parallel.using(2):
        forked, log_forked, _ = optimise_weights(start, poses, obj, max_sweeps=3)
        real_call = parallel.ForkedCall
        monkeypatch.setattr(parallel, "ForkedCall", InProcess)
        here, log_here, _ = optimise_weights(start, poses, obj, max_sweeps=3)
        monkeypatch.setattr(parallel, "ForkedCall", real_call)
        with parallel.allow_fork(False):                   # no fork: the unsplit visit, as everywhere else
            assert np.allclose(optimise_weights(start, poses, obj, max_sweeps=3)[1], log_unsplit, rtol=1e-12, atol=0)
    assert len(calls) == 6
    assert np.allclose(log_forked, log_here, rtol=1e-12, atol=0)
    for name in ("anchor", "twist_weights", "swing_weights"):
        assert np.allclose(getattr(forked, name), getattr(here, name), rtol=0, atol=1e-6)
    assert all(b < a for a, b in zip(log_forked, log_forked[1:]))
    assert abs(obj.value(hybrid_skin(forked, poses)) - log_forked[-1]) <= 1e-9 * log_forked[-1]
    assert abs(log_forked[-1] - log_unsplit[-1]) <= 0.01 * log_unsplit[-1]
    forked.validate()
