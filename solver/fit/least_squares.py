"""Damped least squares (Levenberg–Marquardt): the one iteration loop of the pose fit, the rig learner's
joints-and-poses step and tracking.

A problem is a batch of n independent least-squares problems (n = 1 for a single one) minimising energies
``E_i(x_i) = ‖r_i(x_i)‖²`` (the caller's units, e.g. m²).  Each iteration builds the Gauss–Newton normal
equations ``H = JᵀJ``, ``g = Jᵀr`` at the current parameters, solves a damped system ``(H + μ D) δ = −g``
and accepts the step only if E decreases; the damping rule (:class:`GainRatioDamping`,
:class:`FixedRatioDamping`) lowers μ after an accepted step and raises it after a rejected one, and a
rejected problem tries again with the same normal equations.  The method: dissertation (model-adaptive
mocap) §3.4 (C) (joints and poses with Levenberg damping) and §5.7 (a) (per-frame poses by
Levenberg–Marquardt); docs/learn_rig_solver.md.

The problem implements (``idx``: int array of problem indices, in increasing order):

* ``size``: n;
* ``energy(idx) -> (k,)``: E at the current parameters;
* ``build(idx) -> (k,) or None``: build and keep the normal equations at the current parameters, returning
  the energies if the build computes them (they replace the ones the core holds);
* ``solve(idx, mu) -> steps``: the damped steps for ``mu (k,)``, in the problem's own layout;
* ``try_steps(idx, steps) -> (k,)``: the energies at the current parameters moved by ``steps`` (kept as
  trials; robust weights and priors are the problem's business, and a line search fits here too);
* ``accept(which)``: adopt the trials of the last ``try_steps`` where ``which (k,)`` is True;
* ``predicted_decrease(idx, steps) -> (k,)``: ``−2gᵀδ − δᵀHδ`` (only for :class:`GainRatioDamping`);
* ``step_norm(steps) -> (k,)``: ``‖δ‖``;
* ``slope(idx, steps) -> (k,)``: ``2gᵀδ``, the derivative of E along the step (only with a line search).

Line search (opt-in, ``line_search=ArmijoLineSearch()``): the damped step gives the direction and a
backtracking search its length, as in dissertation (model-adaptive mocap) §4.1.4 ("Levenberg–Marquardt
determines the direction, a line search the step width"); steps must then be arrays with the problems on
the first axis.  Without it every caller's iterations are exactly those of plain Levenberg–Marquardt.
"""
from dataclasses import dataclass

import numpy as np


class GainRatioDamping:
    """μ from the gain ratio ρ = actual / predicted decrease (H. B. Nielsen, *Damping parameter in
    Marquardt's method*, 1999): after an accepted step ``μ ← max(μ · max(1/3, 1 − (2ρ − 1)³), floor)`` (÷3
    only for steps the quadratic model predicted well), after a rejected one ``μ ← increase · μ``.
    ``mu``: a scalar or ``(n,)``; it is updated in place, so a caller that solves the same problem again
    passes the same object and continues where the last call ended."""
    needs_gain_ratio = True

    def __init__(self, mu=1e-3, floor=1e-9, increase=4.0):
        self.mu = np.atleast_1d(np.array(mu, dtype=np.float64))
        self.floor, self.increase = floor, increase

    def accepted(self, idx, rho):
        for i, r in zip(idx, rho):        # scalar arithmetic: the cube is the libm power of every caller
            self.mu[i] = max(self.mu[i] * max(1.0 / 3.0, 1.0 - (2.0 * r - 1.0) ** 3), self.floor)

    def rejected(self, idx):
        self.mu[idx] *= self.increase

    def exhausted(self, idx):
        """Which problems give up (never: the caller limits the rejections)."""
        return np.zeros(len(idx), dtype=bool)


class FixedRatioDamping:
    """μ ← max(μ / decrease, mu_min) after an accepted step, μ ← increase · μ after a rejected one; a
    problem whose μ exceeds mu_max is at a minimum (no decrease even for tiny steps).  ``mu (n,)``."""
    needs_gain_ratio = False

    def __init__(self, mu, decrease=3.0, increase=4.0, mu_min=1e-12, mu_max=1e12):
        self.mu = np.atleast_1d(np.array(mu, dtype=np.float64))
        self.decrease, self.increase, self.mu_min, self.mu_max = decrease, increase, mu_min, mu_max

    def accepted(self, idx, rho=None):
        self.mu[idx] = np.maximum(self.mu[idx] / self.decrease, self.mu_min)

    def rejected(self, idx):
        self.mu[idx] *= self.increase

    def exhausted(self, idx):
        return self.mu[idx] > self.mu_max


class ArmijoLineSearch:
    """Backtracking along the damped step δ: the first ``α`` of ``factors`` (1, 1/2, …, 1/64) with
    ``E(x + αδ) ≤ E(x) + c · α · 2gᵀδ`` (Armijo's sufficient decrease) is taken; if none satisfies it the
    step is rejected and the damping raised, as a plain rejected step.  The accepted step is ``αδ`` (for the
    gain ratio and the step tolerance)."""

    def __init__(self, factors=tuple(0.5 ** k for k in range(7)), c=1e-4):
        self.factors, self.c = tuple(float(a) for a in factors), float(c)

    def search(self, problem, idx, steps, energy):
        """Try ``steps`` of problems ``idx`` at ``energy (k,)``, adopting each problem's first acceptable
        length (``problem.accept`` after each length tried).  Returns ``(E_new (k,), ok (k,), alpha (k,))``
        (alpha 0 where rejected)."""
        steps = np.asarray(steps)
        slope = np.asarray(problem.slope(idx, steps), dtype=np.float64)
        E_new, ok, alpha = energy.copy(), np.zeros(len(idx), dtype=bool), np.zeros(len(idx))
        rows = np.flatnonzero(slope < 0)                    # not a descent direction: rejected outright
        for a in self.factors:
            if not len(rows):
                break
            scale = np.full((len(rows),) + (1,) * (steps.ndim - 1), a)
            E_try = np.asarray(problem.try_steps(idx[rows], scale * steps[rows]), dtype=np.float64)
            good = (E_try <= energy[rows] + self.c * a * slope[rows]) & (E_try < energy[rows])
            if good.any():
                problem.accept(good)
                E_new[rows[good]], ok[rows[good]], alpha[rows[good]] = E_try[good], True, a
            rows = rows[~good]
        return E_new, ok, alpha


@dataclass
class Limits:
    """When a problem stops (None / 0: no such limit or test).

    trials: trial steps (energy evaluations after a solve); steps: accepted steps; rejections: consecutive
    rejected trials; decrease_tol: converged when an accepted step lowers E by at most ``decrease_tol · E``;
    step_tol: converged when an accepted step has ``‖δ‖ ≤ step_tol``; gain_tol: stop when the next decrease,
    extrapolated from the last two (:func:`stalls`), is below ``gain_tol · E``."""
    trials: int = None
    steps: int = None
    rejections: int = None
    decrease_tol: float = 0.0
    step_tol: float = 0.0
    gain_tol: float = 0.0


@dataclass
class Outcome:
    """Per problem ``(n,)``: energy at the end, trial steps and accepted steps taken, and whether a
    tolerance was met (or E = 0, or the damping gave up: a minimum)."""
    energy: np.ndarray
    trials: np.ndarray
    steps: np.ndarray
    converged: np.ndarray


def stalls(previous, decrease, energy, gain_tol):
    """Whether the next decrease, expected as ``d₂²/d₁`` (linear convergence at the observed rate; d₁
    ``previous``, d₂ ``decrease``, NaN: no rate yet), is below ``gain_tol · energy``: a further
    iteration would pay a normal-equation build for almost nothing.  Arrays ``(k,)``."""
    previous, decrease = np.asarray(previous, dtype=np.float64), np.asarray(decrease, dtype=np.float64)
    if gain_tol <= 0:
        return np.zeros(previous.shape, dtype=bool)
    known = previous > 0
    expected = np.divide(decrease * decrease, previous, out=np.full(previous.shape, np.inf), where=known)
    return known & (expected < gain_tol * np.asarray(energy))


def solve_damped(H, g, mu, floor):
    """Steps ``δ (k, P)`` of ``(H + μ D) δ = −g`` with ``D = diag H + floor · mean(diag H)`` per problem
    (Marquardt's scaling; the floor keeps flat directions solvable).  H ``(k, P, P)``, g ``(k, P)``,
    mu ``(k,)``."""
    d = np.diagonal(H, axis1=1, axis2=2)
    D = d + floor * np.maximum(d.mean(axis=1, keepdims=True), 1e-300)
    A = H + (mu[:, None] * D)[:, :, None] * np.eye(d.shape[1])
    return np.linalg.solve(A, -g[..., None])[..., 0]


def levenberg_marquardt(problem, damping, limits, progress=None, line_search=None):
    """Run the problems to their limits (module docstring; the parameters live in ``problem``).

    damping: :class:`GainRatioDamping` or :class:`FixedRatioDamping` with ``mu (n,)``, updated in place;
    limits: :class:`Limits`; line_search: None (plain steps) or :class:`ArmijoLineSearch`.  progress: optional ``progress(idx, iterations, energy)`` after every round in
    which problems ``idx`` ended an iteration (the trials at one normal system: an accepted step, or a stop
    after rejections), ``iterations (k,)`` the normal systems they used.  Returns :class:`Outcome`."""
    n = problem.size
    everyone = np.arange(n)
    trials, steps = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    if any(limit is not None and limit <= 0 for limit in (limits.trials, limits.steps)):
        E = np.asarray(problem.energy(everyone), dtype=np.float64)
        return Outcome(E, trials, steps, E <= 0.0)
    built = problem.build(everyone)
    E = np.array(problem.energy(everyone) if built is None else built, dtype=np.float64)
    state = _State(E, trials, steps, E <= 0.0, np.zeros(n, dtype=np.int64), np.full(n, np.nan), E <= 0.0)
    while not state.done.all():
        act = np.flatnonzero(~state.done)
        accepted, ended = _round(problem, damping, limits, state, act, line_search)
        if progress is not None and len(ended):
            progress(ended, state.steps[ended] + ~np.isin(ended, accepted), state.energy[ended])
        refresh = accepted[~state.done[accepted]]
        if len(refresh):
            built = problem.build(refresh)
            if built is not None:
                state.energy[refresh] = built
    return Outcome(state.energy, state.trials, state.steps, state.converged)


@dataclass
class _State:
    """Per problem: E, trials, accepted steps, converged, consecutive rejections, the last decrease (NaN:
    none yet), stopped."""
    energy: np.ndarray
    trials: np.ndarray
    steps: np.ndarray
    converged: np.ndarray
    rejections: np.ndarray
    last_decrease: np.ndarray
    done: np.ndarray


def _round(problem, damping, limits, st, act, line_search=None):
    """One trial step of every active problem ``act``: solve, try (or search along the step), accept or
    reject, update μ and the stop flags.  Returns ``(accepted, ended)`` problem indices."""
    trial_steps = problem.solve(act, damping.mu[act])
    if line_search is None:
        E_new = np.asarray(problem.try_steps(act, trial_steps), dtype=np.float64)
        ok = E_new < st.energy[act]
    else:
        E_new, ok, alpha = line_search.search(problem, act, trial_steps, st.energy[act])
        trial_steps = alpha.reshape((-1,) + (1,) * (np.ndim(trial_steps) - 1)) * trial_steps
    st.trials[act] += 1
    acc, rej = act[ok], act[~ok]
    decrease = st.energy[acc] - E_new[ok]
    if damping.needs_gain_ratio and len(acc):
        predicted = np.asarray(problem.predicted_decrease(act, trial_steps), dtype=np.float64)[ok]
        rho = np.divide(decrease, predicted, out=np.ones(len(acc)), where=predicted > 0)
        damping.accepted(acc, rho)
    elif len(acc):
        damping.accepted(acc)
    small = (decrease <= limits.decrease_tol * st.energy[acc]) | \
        (np.asarray(problem.step_norm(trial_steps))[ok] <= limits.step_tol) | \
        stalls(st.last_decrease[acc], decrease, E_new[ok], limits.gain_tol)
    if line_search is None:
        problem.accept(ok)
    st.energy[acc], st.last_decrease[acc] = E_new[ok], decrease
    st.steps[acc] += 1
    st.rejections[acc] = 0
    damping.rejected(rej)
    st.rejections[rej] += 1
    stuck = rej[damping.exhausted(rej)]
    st.converged[acc[small]] = st.converged[stuck] = True
    st.done[acc[small]] = st.done[stuck] = True
    for count, limit in ((st.trials, limits.trials), (st.steps, limits.steps), (st.rejections, limits.rejections)):
        if limit is not None:
            st.done[act[count[act] >= limit]] = True
    gave_up = rej[st.done[rej]]
    return acc, np.sort(np.concatenate([acc, gave_up]))
