"""G7 (objective) and G8 (rest vertices by sparse least squares)."""
import copy

import numpy as np
import pytest
import scipy.sparse as sp

from articula.solver.geometry.mesh_graph import kron3, uniform_laplacian
from articula.solver.learn.rest_shape import normal_equations, solve_rest_vertices
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.skinning import affine_form, hybrid_skin

from articula.sample_scenes.tube_scans import hybrid_truth


def test_objective_zero_for_exact_model_and_matches_definition():
    model, poses, scans = hybrid_truth(4)
    L = uniform_laplacian(model.faces, model.num_vertices)
    obj = RigObjective(scans, L, alpha=100.0)
    assert obj.value(scans) == 0.0
    rng = np.random.default_rng(0)
    p = scans + 1e-3 * rng.normal(size=scans.shape)
    d = (p - scans).reshape(len(p), -1)
    Lk = kron3(L)
    brute = sum(d[m] @ d[m] + 100.0 * (Lk @ d[m]) @ (Lk @ d[m]) for m in range(len(p)))
    assert np.isclose(obj.value(p), brute, rtol=1e-12)


@pytest.mark.parametrize("alpha", [0.0, 7.0])
def test_normal_equations_equal_dense_least_squares(alpha):
    model, poses, scans = hybrid_truth(3)
    V = 40                                                     # small dense check on a sub-problem
    A, b = affine_form(model, poses)
    L = uniform_laplacian(model.faces, model.num_vertices)[:V, :V]
    A, b, s = A[:, :V], b[:, :V], scans[:, :V] + 0.01
    N, rhs = normal_equations(A, b, s, L, alpha)
    Lk = kron3(L).toarray()
    rows, tgt = [], []
    for m in range(len(A)):
        D = sp.block_diag(list(A[m])).toarray()
        rows += [D, np.sqrt(alpha) * Lk @ D]
        e = (s[m] - b[m]).ravel()
        tgt += [e, np.sqrt(alpha) * Lk @ e]
    J, y = np.vstack(rows), np.concatenate(tgt)
    assert np.allclose(N.toarray(), J.T @ J, atol=1e-10)
    assert np.allclose(rhs, J.T @ y, atol=1e-10)


def test_rest_vertices_recovered_with_ground_truth_parameters():
    model, poses, scans = hybrid_truth(6)
    L = uniform_laplacian(model.faces, model.num_vertices)
    rng = np.random.default_rng(1)
    for alpha in (0.0, 100.0, 1e4):
        start = copy.deepcopy(model)
        start.rest_vertices = model.rest_vertices + 0.02 * rng.normal(size=model.rest_vertices.shape)
        x = solve_rest_vertices(start, poses, scans, L, alpha)
        assert np.abs(x - model.rest_vertices).max() < 1e-8, alpha


def test_rest_step_never_increases_q():
    model, poses, scans = hybrid_truth(5)
    L = uniform_laplacian(model.faces, model.num_vertices)
    rng = np.random.default_rng(2)
    noisy = scans + 0.003 * rng.normal(size=scans.shape)       # not exactly representable
    obj = RigObjective(noisy, L, 100.0)
    start = copy.deepcopy(model)
    start.rest_vertices = model.rest_vertices + 0.01 * rng.normal(size=model.rest_vertices.shape)
    q0 = obj.value(hybrid_skin(start, poses))
    start.rest_vertices = solve_rest_vertices(start, poses, noisy, L, 100.0)
    q1 = obj.value(hybrid_skin(start, poses))
    assert q1 < q0
    # it is the minimiser: random perturbations of the solution do not decrease Q
    for _ in range(3):
        trial = copy.deepcopy(start)
        trial.rest_vertices = start.rest_vertices + 1e-4 * rng.normal(size=start.rest_vertices.shape)
        assert obj.value(hybrid_skin(trial, poses)) > q1


def test_alpha_trades_position_error_for_local_shape_error():
    """G15 (qualitative): larger α fits the scans' Laplacians better and absolute positions worse."""
    model, poses, scans = hybrid_truth(5)
    L = uniform_laplacian(model.faces, model.num_vertices)
    rng = np.random.default_rng(3)
    noisy = scans + 0.002 * rng.normal(size=scans.shape)
    obj = RigObjective(noisy, L, 1.0)
    terms = []
    for alpha in (0.0, 100.0, 1e4):
        m = copy.deepcopy(model)
        m.rest_vertices = solve_rest_vertices(model, poses, noisy, L, alpha)
        d, l = obj.residuals(hybrid_skin(m, poses))
        terms.append((np.sum(d * d), np.sum(l * l)))
    (d0, l0), (d1, l1), (d2, l2) = terms
    assert d0 < d1 < d2 and l0 > l1 > l2


def _with_rest(model, x):
    m = copy.deepcopy(model)
    m.rest_vertices = x
    return m


def test_conjugate_gradients_reach_the_direct_solution():
    """The preconditioned CG of repeated solves equals the direct sparse solve (and stops early when the
    start already is the solution); with too few iterations it falls back to the direct solve."""
    from articula.solver.learn import rest_shape
    model, poses, scans = hybrid_truth(6)
    L = uniform_laplacian(model.faces, model.num_vertices)
    rng = np.random.default_rng(4)
    noisy = scans + 0.003 * rng.normal(size=scans.shape)
    for alpha in (1.0, 100.0):
        pre = rest_shape.ShapePreconditioner(L, alpha)
        start = copy.deepcopy(model)
        start.rest_vertices = model.rest_vertices + 0.02 * rng.normal(size=model.rest_vertices.shape)
        direct = solve_rest_vertices(start, poses, noisy, L, alpha)
        cg = solve_rest_vertices(start, poses, noisy, L, alpha, pre)
        assert np.abs(cg - direct).max() < 1e-8, alpha                # CG_RTOL 1e-9: nanometres
        obj = RigObjective(noisy, L, alpha)
        q = [obj.value(hybrid_skin(_with_rest(start, x), poses)) for x in (direct, cg)]
        assert abs(q[1] - q[0]) <= 1e-12 * q[0], alpha
        A, b = affine_form(start, poses)
        N, rhs = normal_equations(A, b, noisy, L, alpha)
        x, ok = rest_shape.conjugate_gradients(N, rhs, start.rest_vertices.ravel(), pre.inverse(N))
        assert ok and np.linalg.norm(N @ x - rhs) <= rest_shape.CG_RTOL * np.linalg.norm(rhs)
        _, ok = rest_shape.conjugate_gradients(N, rhs, direct.ravel(), pre.inverse(N), max_iterations=0)
        assert ok                                                   # already converged: no iteration
        _, ok = rest_shape.conjugate_gradients(N, rhs, start.rest_vertices.ravel(), pre.inverse(N),
                                               max_iterations=1)
        assert not ok


def test_conjugate_gradients_fall_back_to_the_direct_solve(monkeypatch):
    from articula.solver.learn import rest_shape
    model, poses, scans = hybrid_truth(4)
    L = uniform_laplacian(model.faces, model.num_vertices)
    start = copy.deepcopy(model)
    start.rest_vertices = model.rest_vertices + 0.01
    monkeypatch.setattr(rest_shape, "CG_MAX_ITERATIONS", 1)
    calls = []
    direct = rest_shape._solve_spd
    monkeypatch.setattr(rest_shape, "_solve_spd", lambda N, rhs: calls.append(1) or direct(N, rhs))
    x = solve_rest_vertices(start, poses, scans, L, 100.0, rest_shape.ShapePreconditioner(L, 100.0))
    assert calls and np.abs(x - model.rest_vertices).max() < 1e-8


def test_with_posed_gives_the_hybrid_skin_of_the_solution():
    """solve_rest_vertices(..., with_posed=True): the same rest vertices, and posed vertices from the affine
    form equal to hybrid_skin of the model with those rest vertices."""
    model, poses, scans = hybrid_truth(5)
    L = uniform_laplacian(model.faces, model.num_vertices)
    noisy = scans + 0.002 * np.random.default_rng(2).normal(size=scans.shape)
    x = solve_rest_vertices(model, poses, noisy, L, 100.0)
    x2, posed = solve_rest_vertices(model, poses, noisy, L, 100.0, with_posed=True)
    assert np.array_equal(x, x2)
    assert np.abs(posed - hybrid_skin(_with_rest(model, x), poses)).max() < 1e-12
    assert np.abs(posed - hybrid_skin(model, poses)).max() > 1e-4          # not the old rest vertices
