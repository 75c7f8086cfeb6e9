"""The GMM/EM pose tracker of one frame (depth-camera tracking dissertation, ch. 6, §6.1-6.3; Algorithms
2-3): the posed model points are the centroids of an isotropic Gaussian mixture with equal priors and a
uniform outlier term (Eq. 6.1-6.2); the E-step gives CPD's posteriors (Eq. 6.4), the M-step solves the
linearised pose update (Eq. 6.7-6.10) with the small-update term E_r and the pull E_p of the joint
rotations towards a predicted pose (Eq. 6.12-6.14), then updates sigma^2 (Eq. 6.11).  sigma^2 starts at
``gmm_sigma^2`` every frame (Table 6.2), never from the data.  Monocular scheme (Algorithm 3): step one
uses the model points inside the view frustum, visible or not; step two only those facing the camera.
Step two has no z-buffer test of the model against itself (ours): a misplaced limb would hide the
model's torso points behind it, and the torso data the camera does see there would then pull the limb
into the torso; points facing the camera but hidden behind other parts usually lie many sigma from any
data and get next to no posterior mass anyway.

E-step truncation (ours): each observed point's posterior is evaluated on its ``gmm_neighbours`` nearest
model points, which also drops the farther components from its normaliser; on a ~1000-point body at
sigma = 2 cm that moves single posteriors by a few hundredths, less as sigma shrinks (k = 5 was as
accurate as 8 on the benchmark, docs/track_depth.md).

Units: the M-step rows are the CPD reduction, one point row per model point m towards ``x~_m / P1_m``
with weight ``P1_m / sigma^2`` (:meth:`solver.tracking.normal_equations.System.add_points`), i.e. twice the
dissertation's ``Q = sum p_mn |x_n - v_m|^2 / (2 sigma^2)``, so the regularisers enter with twice its
weights: damping ``2 lambda_r`` on every parameter (metres, radians) and ``2 lambda_p`` per rad^2 on each
non-root joint's bone-local rotation away from the prediction.  The options hold the lambdas in the
dissertation's units (Table 6.2: lambda_r = 1000, lambda_p = 500).  Joint limits (:mod:`.limits`,
weighted against ICP's unit point rows) are scaled by ``1 / sigma^2`` to keep their strength relative
to the data.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.spatial import cKDTree

from ..rig.model import Poses
from ..tracking.lm import iterate
from ..tracking.normal_equations import System
from ..tracking.priors import toward_bones
from .icp import MAX_TURN, FrameFit, coverage
from .visibility import facing, in_view

SIGMA_FLOOR = 0.002      # metres: sigma never drops below this (exact data would make it vanish)
MIN_MASS = 1e-6          # model points with less posterior mass than this get no row


def outlier_constant(sigma2: float, outliers: float, M: int, N: int) -> float:
    """``u_c = (2 pi sigma^2)^(3/2) u M / ((1 - u) N)`` of Eq. 6.4 (the uniform term in the normaliser)."""
    return (2.0 * np.pi * sigma2) ** 1.5 * outliers * M / ((1.0 - outliers) * N)


def posterior(x: np.ndarray, v: np.ndarray, sigma2: float, outliers: float, neighbours=None):
    """E-step (Eq. 6.4) for observed points ``x`` (N, 3) and model points ``v`` (M, 3): ``(idx, p)``
    both (N, k), ``p[n, i]`` the posterior of component ``idx[n, i]`` for point n.  ``neighbours``
    (k) truncates each point to its k nearest components (None or >= M: all, exact)."""
    N, M = len(x), len(v)
    if neighbours is None or neighbours >= M:
        idx = np.broadcast_to(np.arange(M), (N, M))
        d2 = ((x[:, None, :] - v[None]) ** 2).sum(axis=2)
    else:
        d, idx = cKDTree(v).query(x, neighbours)
        d2 = d.reshape(N, -1) ** 2
        idx = idx.reshape(N, -1)
    g = np.exp(-d2 / (2.0 * sigma2))
    denom = g.sum(axis=1, keepdims=True) + outlier_constant(sigma2, outliers, M, N)
    return idx, g / np.maximum(denom, 1e-300)


def reduce(x: np.ndarray, idx: np.ndarray, p: np.ndarray, M: int):
    """CPD reduction: ``P1`` (M,) = sum_n p_mn and ``PX`` (M, 3) = sum_n p_mn x_n."""
    flat, w = idx.ravel(), p.ravel()
    P1 = np.bincount(flat, w, minlength=M)
    xs = np.repeat(x, idx.shape[1], axis=0)
    PX = np.stack([np.bincount(flat, w * xs[:, c], minlength=M) for c in range(3)], axis=1)
    return P1, PX


def sigma2_update(x: np.ndarray, v: np.ndarray, idx: np.ndarray, p: np.ndarray) -> float:
    """Eq. 6.11: ``sum p_mn |x_n - v_m|^2 / (3 P)`` with the model points ``v`` after the step."""
    d2 = ((x[:, None, :] - v[idx]) ** 2).sum(axis=2)
    return float((p * d2).sum() / max(3.0 * p.sum(), 1e-12))


def prediction_term(body, predicted: Poses, weight: float):
    """E_p (Eq. 6.13): rows ``log(q_pred_b^-1 q_b)`` on every non-root joint's local rotation, each adding
    ``weight J^T J`` to the normal matrix (:func:`solver.tracking.priors.toward_bones`)."""
    return toward_bones(predicted, body.size, np.flatnonzero(np.asarray(body.model.skeleton.parents) >= 0), weight)


def _active(posed, camera, step: int) -> np.ndarray:
    """Model points of the step: in the view frustum (step one), also facing the camera (step two); all
    of them without a camera."""
    if camera is None:
        return np.arange(len(posed.points))
    uv, z = camera.project(posed.points)
    ok = in_view(uv, z, camera.intr)
    return np.flatnonzero(ok if step == 1 else ok & facing(posed.points, posed.normals, camera.centre))


@dataclasses.dataclass
class EMState:
    """``pose`` (one frame), ``sigma2`` (m^2), EM ``iterations`` so far, posterior ``mass`` P of the last
    E-step (Eq. 6.6), ``posed`` the body posed by ``pose`` once known."""
    pose: Poses
    sigma2: float
    iterations: int = 0
    mass: float = 0.0
    posed: object = None


class Mixture:
    """The GMM data term of one step of Algorithm 3 (``step`` 1 or 2) on the observed points ``x`` (N, 3),
    for :func:`solver.tracking.lm.iterate`: at every pose the active model points (:func:`_active`) and
    their E-step (Eq. 6.4; None below 10 points or a mass of 6), the M-step's point rows of the CPD
    reduction plus E_p (``pull``); the priors weigh ``1 / sigma^2`` (``prior_scale``).  After each step
    sigma^2 is updated (Eq. 6.11) and it has converged when no active point moved ``gmm_converged_m``."""

    def __init__(self, x, camera, opts, pull, step: int, sigma2: float):
        self.x, self.camera, self.opts, self.pull, self.step, self.sigma2 = x, camera, opts, pull, step, sigma2
        self.mass = 0.0
        self._e = None

    @property
    def prior_scale(self) -> float:
        return 1.0 / self.sigma2

    def linearise(self, body, posed):
        rows = _active(posed, self.camera, self.step)
        if len(rows) < 10:
            return None
        idx, p = posterior(self.x, posed.points[rows], self.sigma2, self.opts.gmm_outliers, self.opts.gmm_neighbours)
        P1, PX = reduce(self.x, idx, p, len(rows))
        self.mass = float(P1.sum())
        if self.mass < 6:
            return None
        self._e = rows, idx, p
        keep = P1 > MIN_MASS
        rows, P1, PX = rows[keep], P1[keep], PX[keep]
        system = System(body, posed)
        system.add_points(body.lever_arms(posed, rows), posed.points[rows] - PX / P1[:, None], P1 / self.sigma2)
        lin = system.linear()
        return lin if self.pull is None else lin + self.pull.linearise(body, posed)

    def converged(self, body, posed, moved, step) -> bool:
        rows, idx, p = self._e
        self.sigma2 = max(sigma2_update(self.x, moved.points[rows], idx, p), SIGMA_FLOOR ** 2)
        return np.linalg.norm(moved.points[rows] - posed.points[rows], axis=1).max() < self.opts.gmm_converged_m


def em(body, x, camera, state: EMState, opts, prior, pull, step: int, max_iterations: int) -> EMState:
    """EM iterations (Algorithm 2) of step ``step`` (1 or 2) of Algorithm 3 on the observed points ``x``
    (N, 3) with the limits ``prior`` and E_p ``pull``, from and into ``state`` (:class:`Mixture`): the
    damped M-step (``2 lambda_r``, Eq. 6.10) until no active model point moves more than
    ``gmm_converged_m``."""
    data = Mixture(x, camera, opts, pull, step, state.sigma2)
    state.pose, state.posed, it = iterate(body, state.pose, data, prior, 2.0 * opts.gmm_lambda_r, MAX_TURN,
                                          max_iterations, posed=state.posed)
    state.iterations += it
    state.sigma2, state.mass = data.sigma2, data.mass
    return state


def sample(obs, count: int) -> np.ndarray:
    """(n, 3) about ``count`` observed points: every k-th of the grid-sampled observation."""
    return obs.points[:: max(1, int(np.ceil(len(obs.points) / max(count, 1))))]


def fit_frame(body, obs, camera, pose, opts, prior=(), iterations=None, predicted=None) -> FrameFit:
    """Algorithm 3 from ``pose`` (one frame) on the observation ``obs``: step one on the model points in
    view, step two on those facing the camera, each at most ``iterations`` (default ``gmm_iterations``) EM
    iterations.  ``predicted`` (one frame, e.g. :func:`solver.tracking.motion.extrapolate` of the last two poses, usually
    also the start ``pose``) is the target of E_p; without it the start pose is.  ``prior``: terms of
    :mod:`solver.tracking.priors` (joint limits).
    Without a ``camera`` (complete data, e.g. a scan) one step with every model point.
    ``FrameFit.pairs`` is the posterior mass P (observed points the model explains), ``edges`` 0."""
    t0 = time.perf_counter()
    cap = iterations or opts.gmm_iterations
    predicted = pose if predicted is None else predicted
    pull = prediction_term(body, predicted, 2.0 * opts.gmm_lambda_p) if opts.gmm_lambda_p > 0 else None
    state = EMState(pose, opts.gmm_sigma ** 2)
    if not obs.empty:
        x = sample(obs, opts.gmm_points)
        for step in ((1, 2) if camera is not None else (1,)):
            state = em(body, x, camera, state, opts, prior, pull, step, cap)
    posed = state.posed if state.posed is not None else body.pose(state.pose)
    share, mean = coverage(body, posed, obs, opts.near_m)
    return FrameFit(state.pose, state.iterations, int(round(state.mass)), 0, share, mean,
                    time.perf_counter() - t0, posed)
