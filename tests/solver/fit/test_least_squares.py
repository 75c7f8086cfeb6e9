"""The damped least-squares core (solver.fit.least_squares) against closed forms and scipy's least_squares."""
import numpy as np
import pytest
from scipy.optimize import least_squares as scipy_least_squares

from articula.solver.fit.least_squares import (ArmijoLineSearch, FixedRatioDamping, GainRatioDamping, Limits,
                                               levenberg_marquardt, solve_damped, stalls)


class Dense:
    """n problems with parameters ``x (n, P)``, residuals ``residual(x, idx) (k, m)`` and Jacobians
    ``jacobian(x, idx) (k, m, P)`` of the problems ``idx``: the core's problem protocol in its plainest form."""

    def __init__(self, residual, jacobian, x0):
        self.residual, self.jacobian = residual, jacobian
        self.x = np.array(x0, dtype=np.float64)
        self.size, P = self.x.shape
        self.H, self.g = np.zeros((self.size, P, P)), np.zeros((self.size, P))
        self.builds = []

    def _energy(self, x, idx):
        r = self.residual(x, idx)
        return np.einsum("km,km->k", r, r)

    def energy(self, idx):
        return self._energy(self.x[idx], idx)

    def build(self, idx):
        self.builds.append(idx.copy())
        J, r = self.jacobian(self.x[idx], idx), self.residual(self.x[idx], idx)
        self.H[idx], self.g[idx] = np.einsum("kmi,kmj->kij", J, J), np.einsum("kmi,km->ki", J, r)
        return None

    def solve(self, idx, mu):
        return solve_damped(self.H[idx], self.g[idx], mu, 1e-9)

    def try_steps(self, idx, steps):
        self.trial = idx, self.x[idx] + steps
        return self._energy(self.trial[1], idx)

    def accept(self, which):
        idx, x = self.trial
        self.x[idx[which]] = x[which]

    def predicted_decrease(self, idx, steps):
        return -2.0 * np.einsum("ki,ki->k", self.g[idx], steps) - np.einsum("ki,kij,kj->k", steps, self.H[idx], steps)

    def step_norm(self, steps):
        return np.linalg.norm(steps, axis=1)

    def slope(self, idx, steps):
        return 2.0 * np.einsum("ki,ki->k", self.g[idx], steps)


def _rules(n):
    return [GainRatioDamping(np.full(n, 1e-3)), FixedRatioDamping(np.full(n, 1e-3))]


def _linear(seed=0, n=3, m=12, P=4, sign=1.0):
    """Random inconsistent ``r = A x − b`` (sign −1: the Jacobian has the wrong sign, every step goes uphill)."""
    rng = np.random.default_rng(seed)
    A, b = rng.normal(size=(n, m, P)), rng.normal(size=(n, m))
    return A, b, Dense(lambda x, idx: np.einsum("kmp,kp->km", A[idx], x) - b[idx],
                       lambda x, idx: sign * A[idx], rng.normal(size=(n, P)))


@pytest.mark.parametrize("rule", [0, 1])
def test_linear_problem_reaches_the_closed_form_solution(rule):
    """r = A x − b: the minimiser is the least-squares solution (normal equations), for every problem of
    the batch, whatever the damping rule; the iteration stops on its tolerances or, at the minimum, after
    rejected trials."""
    A, b, prob = _linear()
    out = levenberg_marquardt(prob, _rules(3)[rule],
                              Limits(trials=100, rejections=20, decrease_tol=1e-15, step_tol=1e-12))
    exact = np.stack([np.linalg.lstsq(a, y, rcond=None)[0] for a, y in zip(A, b)])
    assert np.abs(prob.x - exact).max() < 1e-9
    r = np.einsum("kmp,kp->km", A, exact) - b
    assert np.allclose(out.energy, np.sum(r * r, axis=1), rtol=1e-12)
    assert (out.trials < 100).all() and (out.steps < 10).all()


def _exponential(t, y):
    def residual(x, idx=None):
        return x[:, :1] * np.exp(x[:, 1:2] * t) + x[:, 2:3] - y

    def jacobian(x, idx=None):
        e = np.exp(x[:, 1:2] * t)
        return np.stack([e, x[:, :1] * t * e, np.ones_like(e)], axis=2)
    return residual, jacobian


@pytest.mark.parametrize("rule", [0, 1])
def test_exponential_fit_matches_scipy(rule):
    """y = a exp(b t) + c with noise, from two starts: the minimum scipy's least_squares finds."""
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 2.0, 25)
    y = 2.0 * np.exp(-1.3 * t) + 0.5 + rng.normal(scale=0.02, size=t.shape)
    residual, jacobian = _exponential(t, y)
    starts = np.array([[1.0, -0.5, 0.0], [4.0, -3.0, 1.0]])
    prob = Dense(residual, jacobian, starts)
    out = levenberg_marquardt(prob, _rules(2)[rule], Limits(trials=200, decrease_tol=1e-14, step_tol=1e-12))
    ref = scipy_least_squares(lambda x: residual(x[None])[0], starts[0], jac=lambda x: jacobian(x[None])[0],
                              method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert out.converged.all()
    assert np.abs(prob.x - ref.x).max() < 1e-7
    assert np.allclose(out.energy, 2 * ref.cost, rtol=1e-10)          # scipy's cost is ½‖r‖²


@pytest.mark.parametrize("rule", [0, 1])
def test_rosenbrock_reaches_its_minimum(rule):
    """r = (10 (x₂ − x₁²), 1 − x₁) from the classical start (−1.2, 1): the minimum (1, 1), E = 0."""
    def residual(x, idx=None):
        return np.stack([10.0 * (x[:, 1] - x[:, 0] ** 2), 1.0 - x[:, 0]], axis=1)

    def jacobian(x, idx=None):
        k = len(x)
        return np.stack([np.stack([-20.0 * x[:, 0], np.full(k, 10.0)], axis=1),
                         np.stack([-np.ones(k), np.zeros(k)], axis=1)], axis=1)
    prob = Dense(residual, jacobian, [[-1.2, 1.0]])
    out = levenberg_marquardt(prob, _rules(1)[rule], Limits(trials=500, decrease_tol=1e-15, step_tol=1e-13))
    assert np.abs(prob.x - 1.0).max() < 1e-6 and out.energy[0] < 1e-12
    ref = scipy_least_squares(lambda x: residual(x[None])[0], [-1.2, 1.0], method="lm")
    assert np.abs(prob.x[0] - ref.x).max() < 1e-6


def _arctan_problem(x0):
    """r = atan(x): from |x| ≳ 1.4 the Gauss–Newton step overshoots to a larger |atan|."""
    return Dense(lambda x, idx: np.arctan(x), lambda x, idx: (1.0 / (1.0 + x * x))[:, :, None], np.array(x0)[:, None])


@pytest.mark.parametrize("rule", [0, 1])
def test_a_step_that_raises_the_energy_is_rejected_and_the_damping_raised(rule):
    prob = _arctan_problem([2.0])
    damping = _rules(1)[rule]
    E0 = prob.energy(np.arange(1))
    out = levenberg_marquardt(prob, damping, Limits(trials=1))
    assert out.trials[0] == 1 and out.steps[0] == 0 and not out.converged[0]
    assert prob.x[0, 0] == 2.0 and out.energy[0] == E0[0]              # the parameters did not move
    assert damping.mu[0] == 4e-3
    assert len(prob.builds) == 1                                        # no new system after a rejection
    out = levenberg_marquardt(prob, damping, Limits(trials=100, decrease_tol=1e-15, step_tol=1e-12))
    assert abs(prob.x[0, 0]) < 1e-6 and out.steps[0] >= 1


def test_rejections_and_exhausted_damping_stop_a_problem_that_cannot_improve():
    """With a wrong-signed Jacobian every trial goes uphill: a rejection limit stops the problem unconverged
    after that many trials (μ ×4 each), the ÷3/×4 rule's μ_max stops it as converged."""
    prob = _linear(n=1, sign=-1.0)[2]
    x0 = prob.x.copy()
    damping = GainRatioDamping()
    out = levenberg_marquardt(prob, damping, Limits(steps=5, rejections=12))
    assert out.trials[0] == 12 and out.steps[0] == 0 and not out.converged[0]
    assert np.isclose(damping.mu[0], 1e-3 * 4.0 ** 12) and np.array_equal(prob.x, x0)
    out = levenberg_marquardt(_linear(n=1, sign=-1.0)[2], FixedRatioDamping([1.0], mu_max=1e3), Limits(trials=50))
    assert out.converged[0] and out.steps[0] == 0 and out.trials[0] == 5          # 4⁵ > 1e3 ≥ 4⁴


def test_systems_are_built_only_for_iterations_that_run_and_progress_counts_them():
    """k accepted steps under a step limit need k systems; progress reports each iteration's end."""
    A, b, prob = _linear(n=2)
    calls = []
    out = levenberg_marquardt(prob, GainRatioDamping([1e-3, 1e-3]), Limits(steps=3),
                              lambda idx, used, energy: calls.append((idx.tolist(), used.tolist())))
    assert out.steps.tolist() == [3, 3] and len(prob.builds) == 3
    assert calls == [([0, 1], [1, 1]), ([0, 1], [2, 2]), ([0, 1], [3, 3])]
    zero = levenberg_marquardt(_linear(n=2)[2], GainRatioDamping([1e-3, 1e-3]), Limits(steps=0))
    assert zero.trials.tolist() == [0, 0] and not zero.converged.any()


def test_gain_ratio_rule():
    """μ: ÷3 after a step the quadratic model predicted exactly, unchanged at ρ = 1/2, ×2 as ρ → 0, ×4 after a
    rejection, never below the floor."""
    d = GainRatioDamping(1.0)
    idx = np.array([0])
    d.accepted(idx, [1.0])
    assert np.isclose(d.mu[0], 1 / 3)
    d.accepted(idx, [0.5])
    assert np.isclose(d.mu[0], 1 / 3)
    d.accepted(idx, [1e-12])
    assert np.isclose(d.mu[0], 2 / 3)
    d.rejected(idx)
    assert np.isclose(d.mu[0], 8 / 3)
    tiny = GainRatioDamping(1e-9)
    tiny.accepted(idx, [1.0])
    assert tiny.mu[0] == 1e-9


def test_fixed_ratio_rule():
    d = FixedRatioDamping([1.0, 3e-12, 1e12])
    d.accepted(np.array([0, 1]))
    assert d.mu[0] == 1 / 3 and d.mu[1] == 1e-12
    d.rejected(np.array([2]))
    assert d.exhausted(np.arange(3)).tolist() == [False, False, True]


def test_stalls_in_closed_form():
    """Decreases d₁, d₂ expect d₂²/d₁ next, compared with gain_tol · E; no rate without d₁; 0 never stops."""
    assert not stalls([np.nan], [1.0], [9.0], 0.5)[0]
    assert stalls([1.0], [0.1], [8.9], 0.011 / 8.9 + 1e-12)[0]
    assert not stalls([1.0], [0.1], [8.9], 0.009 / 8.9)[0]
    assert not stalls([1.0], [0.1], [8.9], 0.0)[0]


def test_solve_damped_equals_the_explicit_system():
    rng = np.random.default_rng(2)
    J = rng.normal(size=(2, 7, 3))
    H, g, mu = np.einsum("kmi,kmj->kij", J, J), rng.normal(size=(2, 3)), np.array([0.1, 10.0])
    step = solve_damped(H, g, mu, 1e-6)
    for k in range(2):
        d = np.diag(H[k])
        A = H[k] + mu[k] * np.diag(d + 1e-6 * d.mean())
        assert np.allclose(A @ step[k], -g[k], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("rule", [0, 1])
def test_line_search_halves_a_step_that_overshoots(rule):
    """atan from x = 2: the Gauss–Newton step δ = −5 atan 2 lands at a larger |atan| (plain LM rejects it,
    test above); the line search takes α = 1/2 of it in the same trial: x = 2 − 2.5 atan 2, lower E."""
    prob = _arctan_problem([2.0])
    damping = [GainRatioDamping([1e-12]), FixedRatioDamping([1e-12])][rule]
    E0 = prob.energy(np.arange(1))[0]
    out = levenberg_marquardt(prob, damping, Limits(trials=1), line_search=ArmijoLineSearch())
    assert out.trials[0] == 1 and out.steps[0] == 1
    assert np.isclose(prob.x[0, 0], 2.0 - 2.5 * np.arctan(2.0), rtol=1e-9)
    assert out.energy[0] == np.arctan(prob.x[0, 0]) ** 2 < E0


def test_line_search_takes_each_problem_s_own_length_and_reaches_the_minima():
    """Two problems in one batch: a linear one (full step), atan from 2 (half step); then both to 0."""
    def residual(x, idx):
        return np.where((np.asarray(idx) == 0)[:, None], x - 1.0, np.arctan(x))

    def jacobian(x, idx):
        return np.where((np.asarray(idx) == 0)[:, None], 1.0, 1.0 / (1.0 + x * x))[:, :, None]
    prob = Dense(residual, jacobian, [[3.0], [2.0]])
    search = ArmijoLineSearch()
    levenberg_marquardt(prob, FixedRatioDamping([1e-12, 1e-12]), Limits(trials=1), line_search=search)
    assert np.isclose(prob.x[0, 0], 1.0, atol=1e-9)
    assert np.isclose(prob.x[1, 0], 2.0 - 2.5 * np.arctan(2.0), rtol=1e-9)
    out = levenberg_marquardt(prob, FixedRatioDamping([1e-3, 1e-3]), Limits(trials=100, decrease_tol=1e-15,
                                                                             step_tol=1e-12), line_search=search)
    assert np.abs(prob.x - [[1.0], [0.0]]).max() < 1e-6 and out.energy.max() < 1e-12


def test_line_search_rejects_an_uphill_direction_and_raises_the_damping():
    """A wrong-signed Jacobian: no length passes Armijo's test, the step is rejected as in plain LM."""
    prob = _linear(n=1, sign=-1.0)[2]
    x0 = prob.x.copy()
    damping = FixedRatioDamping([1e-3])
    out = levenberg_marquardt(prob, damping, Limits(trials=3), line_search=ArmijoLineSearch())
    assert out.steps[0] == 0 and out.trials[0] == 3 and np.array_equal(prob.x, x0)
    assert np.isclose(damping.mu[0], 1e-3 * 4.0 ** 3)


def test_armijo_condition_in_closed_form():
    """E(α) = (1 − α)² from E = 1 along δ = 1 (slope −2): α = 1 passes; with c = 0.9 only α ≤ 0.2 would,
    so the first passing factor of (1, ½, ¼, …) is ⅛."""
    class Quadratic:
        def __init__(self):
            self.x, self.tried = np.zeros(1), []

        def slope(self, idx, steps):
            return -2.0 * steps[:, 0]

        def try_steps(self, idx, steps):
            self.tried.append(steps[0, 0])
            self.trial = steps[:, 0]
            return (1.0 - steps[:, 0]) ** 2

        def accept(self, which):
            self.x[which] = self.trial[which]
    q = Quadratic()
    E, ok, alpha = ArmijoLineSearch().search(q, np.arange(1), np.ones((1, 1)), np.ones(1))
    assert ok[0] and alpha[0] == 1.0 and E[0] == 0.0 and q.x[0] == 1.0
    q = Quadratic()
    E, ok, alpha = ArmijoLineSearch(c=0.9).search(q, np.arange(1), np.ones((1, 1)), np.ones(1))
    assert ok[0] and alpha[0] == 0.125 and q.tried == [1.0, 0.5, 0.25, 0.125] and q.x[0] == 0.125
