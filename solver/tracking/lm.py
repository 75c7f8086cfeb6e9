"""One robust Levenberg–Marquardt over a frame's parameters, for any list of terms (:mod:`.terms`,
:mod:`.priors`).

Each iteration linearises every term at the current pose (IRLS weights, correspondences found at that
pose), solves ``(H + mu diag(H)) step = -g``, and accepts the step when the energy re-evaluated at the
trial pose (correspondences re-found there) is lower; mu falls on acceptance and rises on rejection
(Nielsen's rule on the gain ratio).  It stops when an accepted step moves no bone by more than
``step_rad`` and the root by no more than ``step_m``, or after ``max_iterations`` linearisations; a
rejected step ends it when it was nearly that small or when the linear model promised less than
``REJECTED_GAIN`` of the energy: what is left is below the energy's kinks (capture points switching
between neighbouring fingers or triangles change it by more than that).

Fits that re-find their correspondences after every step instead of testing it (the depth trackers'
ICP and EM iterations) run :func:`iterate`: damped Gauss–Newton steps (:func:`gauss_newton_step`) on the
same linearisations, every term and prior alike.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.linalg import cho_factor, cho_solve

REJECTED_SLACK = 5.0     # a rejected step this close to the tolerance ends the fit
REJECTED_GAIN = 1e-3     # ... as does one whose predicted decrease is below this share of the energy


@dataclasses.dataclass(frozen=True)
class Stopping:
    """When the fit stops: ``max_iterations`` linearisations; an accepted step below ``step_rad``
    (largest bone rotation, radians) and ``step_m`` (root translation, metres), or lowering the energy
    by less than ``rel_energy`` of it; a rejected step within ``REJECTED_SLACK`` times those, or one whose
    predicted decrease is below ``REJECTED_GAIN`` of the energy."""
    max_iterations: int = 15
    step_rad: float = 2e-4
    step_m: float = 5e-5
    rel_energy: float = 1e-4
    mu: float = 1e-4


@dataclasses.dataclass
class Fit:
    """Result of :func:`minimise`: the pose, its energy, iterations used, whether the step test stopped it."""
    pose: object
    energy: float
    iterations: int
    converged: bool
    data: object = None


class State:
    """A pose with its posed mesh and surface, evaluated once."""

    def __init__(self, body, pose, slot=0):
        self.pose, self.slot = pose, slot
        self.posed = body.pose(pose)
        self.surface = body.surface(self.posed)
        self.cache = {}

    def energy(self, body, terms) -> float:
        return sum(t.energy(body, self) for t in terms)

    def linearise(self, body, terms):
        return linearise_sum(terms, body, self)


def minimise(body, start, terms, stopping: Stopping = Stopping(), cancel=None) -> Fit:
    """Minimise the sum of ``terms`` over one frame's parameters from ``start`` (one frame's Poses, or a
    :class:`State` whose cached pairs then serve the first linearisation)."""
    state = start if isinstance(start, State) else State(body, start)
    mu, nu, it, converged = stopping.mu, 2.0, 0, False
    lin = state.linearise(body, terms)
    energy = lin.energy
    while it < stopping.max_iterations:
        it += 1
        if cancel is not None:
            cancel()
        step = damped_step(lin.H, lin.g, mu)
        trial = State(body, body.moved(state.pose, step), state.slot)
        e_trial = trial.energy(body, terms)
        predicted = -(step @ lin.g) - 0.5 * step @ lin.H @ step
        gain = (energy - e_trial) / max(predicted, 1e-300)
        if e_trial < energy:
            state, done = trial, small_step(step, stopping) or energy - e_trial <= stopping.rel_energy * energy
            energy = e_trial
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
            nu = 2.0
            if done:
                converged = True
                break
            lin = state.linearise(body, terms)
            energy = lin.energy
        else:
            mu *= nu
            nu *= 2.0
            if small_step(step, stopping, REJECTED_SLACK) or predicted <= REJECTED_GAIN * energy:
                converged = True       # the energy's kinks (pairs switching) are below the tolerances
                break
    return Fit(state.pose, energy, it, converged, state)


def damped_step(H, g, mu):
    """``-(H + mu (diag(H) + tiny)) ^-1 g``, by Cholesky when it factors, else least squares."""
    d = np.diag(H).copy()
    A = H + np.diag(mu * (d + 1e-12 * max(float(d.max(initial=0.0)), 1e-30)))
    try:
        return -cho_solve(cho_factor(A, check_finite=False), g, check_finite=False)
    except np.linalg.LinAlgError:
        return -np.linalg.lstsq(A, g, rcond=None)[0]


def gauss_newton_step(lin, damping: float, max_turn: float = None) -> np.ndarray:
    """``-(H + damping I)^-1 g``: the step minimising the linearisation ``lin`` plus ``damping |step|^2``
    (the depth-camera dissertation's small-update term E_r, ch. 5 Eq. 5.6, ch. 6 Eq. 6.10), for fits
    that re-find their correspondences after every step (ICP, EM) instead of testing it; shortened so
    that no bone turns by more than ``max_turn`` radians."""
    A = lin.H + damping * np.eye(len(lin.g))
    try:
        step = -cho_solve(cho_factor(A, check_finite=False), lin.g, check_finite=False)
    except np.linalg.LinAlgError:
        step = -np.linalg.lstsq(A, lin.g, rcond=None)[0]
    if max_turn is not None:
        turn = np.linalg.norm(step[3:].reshape(-1, 3), axis=1).max(initial=0.0)
        if turn > max_turn:
            step = step * (max_turn / turn)
    return step


def iterate(body, pose, data, priors=(), damping: float = 0.0, max_turn: float = None,
            max_iterations: int = 10, posed=None):
    """Damped Gauss–Newton iterations for data terms that re-find their correspondences after every step
    (the depth trackers' ICP and EM): at each pose ``data.linearise(body, posed)`` (None: too little
    data, stop) plus the ``priors`` weighted by ``data.prior_scale`` give the step
    (:func:`gauss_newton_step`); ``data.converged(body, posed, moved, step)`` ends it.  ``pose``: one
    frame (``posed``: the body at it, when known); returns ``(pose, posed, iterations)`` with ``posed`` the
    body at the final pose."""
    posed = body.pose(pose) if posed is None else posed
    it = 0
    while it < max_iterations:
        lin = data.linearise(body, posed)
        if lin is None:
            break
        it += 1
        if priors:
            lin = lin + linearise_sum(priors, body, posed).scaled(data.prior_scale)
        step = gauss_newton_step(lin, damping, max_turn)
        pose = body.moved(pose, step)
        moved = body.pose(pose)
        done = data.converged(body, posed, moved, step)
        posed = moved
        if done:
            break
    return pose, posed, it


def linearise_sum(terms, body, state):
    """The sum of ``terms``' linearisations at ``state`` (None for no terms)."""
    lin = None
    for t in terms:
        one = t.linearise(body, state)
        lin = one if lin is None else lin + one
    return lin


def small_step(step, stopping: Stopping, slack: float = 1.0) -> bool:
    """True when no bone turns by more than ``slack * step_rad`` and the root moves less than
    ``slack * step_m``."""
    rot = step[3:].reshape(-1, 3)
    return (np.linalg.norm(rot, axis=1).max(initial=0.0) <= slack * stopping.step_rad
            and np.linalg.norm(step[:3]) <= slack * stopping.step_m)
