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
with weight ``P1_m / sigma^2`` (:meth:`.normal_equations.System.add_points`), i.e. twice the
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

from ..geometry.rotations import quat_conj, quat_mul, quat_to_rotvec
from ..rig.model import Poses
from ..tracking.pose_prior import rotvec_increment_jacobian
from .icp import MAX_TURN, FrameFit, coverage
from .normal_equations import System
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


def add_prediction(system: System, body, posed, pose: Poses, predicted: Poses, weight: float) -> None:
    """E_p (Eq. 6.13) as rows ``weight |log(q_b q_pred_b^-1)|^2`` on every non-root joint's local rotation;
    a world increment omega_b changes the local rotation by the left increment ``F_bᵀ W_pᵀ omega_b``
    (:meth:`.body.TrackingBody.apply`), so the rows are ``J_l^-1(d) F_bᵀ W_pᵀ``."""
    sk = body.model.skeleton
    b = np.flatnonzero(np.asarray(sk.parents) >= 0)
    if len(b) == 0 or weight <= 0:
        return
    d = quat_to_rotvec(quat_mul(pose.rotations[0, b], quat_conj(predicted.rotations[0, b])))
    to_local = np.swapaxes(sk.frames[b], 1, 2) @ np.swapaxes(posed.world[sk.parents[b]], 1, 2)
    D = rotvec_increment_jacobian(-d) @ to_local                     # (k, 3, 3) rows of each bone's block
    cols = 3 + 3 * b[:, None] + np.arange(3)                         # (k, 3) parameter ids of the blocks
    system.H[cols[:, :, None], cols[:, None, :]] += weight * np.swapaxes(D, 1, 2) @ D
    system.g[cols] += weight * np.einsum("kri,kr->ki", D, d)
    system.energy += weight * float((d * d).sum())


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


def _m_step(body, posed, pose, rows, P1, PX, sigma2, opts, prior, predicted):
    """The damped step (3 + 3B,) of Eq. 6.10 with E_r, E_p and the scaled joint limits."""
    keep = P1 > MIN_MASS
    rows, P1, PX = rows[keep], P1[keep], PX[keep]
    system = System(body.num_bones)
    a = body.lever_arms(posed, rows)
    system.add_points(a, posed.points[rows] - PX / P1[:, None], P1 / sigma2)
    if predicted is not None:
        add_prediction(system, body, posed, pose, predicted, 2.0 * opts.gmm_lambda_p)
    if prior is not None:
        limits = System(body.num_bones)
        prior.add_to(limits, posed, pose)
        system.H += limits.H / sigma2
        system.g += limits.g / sigma2
    delta = system.solve(2.0 * opts.gmm_lambda_r)
    turn = np.linalg.norm(delta[3:].reshape(-1, 3), axis=1).max(initial=0.0)
    return delta * (MAX_TURN / turn) if turn > MAX_TURN else delta


def em(body, x, camera, state: EMState, opts, prior, predicted, step: int, max_iterations: int) -> EMState:
    """EM iterations (Algorithm 2) of step ``step`` (1 or 2) of Algorithm 3 on the observed points ``x``
    (N, 3), from and into ``state``, until no active model point moves more than ``gmm_converged_m``;
    the active points are chosen again every iteration."""
    posed = state.posed if state.posed is not None else body.pose(state.pose)
    for _ in range(max_iterations):
        rows = _active(posed, camera, step)
        if len(rows) < 10:
            break
        idx, p = posterior(x, posed.points[rows], state.sigma2, opts.gmm_outliers, opts.gmm_neighbours)
        P1, PX = reduce(x, idx, p, len(rows))
        state.mass = float(P1.sum())
        if state.mass < 6:
            break
        delta = _m_step(body, posed, state.pose, rows, P1, PX, state.sigma2, opts, prior, predicted)
        state.pose = body.apply(state.pose, delta, posed)
        state.iterations += 1
        moved = posed.points[rows]
        posed = body.pose(state.pose)
        state.sigma2 = max(sigma2_update(x, posed.points[rows], idx, p), SIGMA_FLOOR ** 2)
        if np.linalg.norm(posed.points[rows] - moved, axis=1).max() < opts.gmm_converged_m:
            break
    state.posed = posed
    return state


def sample(obs, count: int) -> np.ndarray:
    """(n, 3) about ``count`` observed points: every k-th of the grid-sampled observation."""
    return obs.points[:: max(1, int(np.ceil(len(obs.points) / max(count, 1))))]


def fit_frame(body, obs, camera, pose, opts, prior=None, iterations=None, predicted=None) -> FrameFit:
    """Algorithm 3 from ``pose`` (one frame) on the observation ``obs``: step one on the model points in
    view, step two on those facing the camera, each at most ``iterations`` (default ``gmm_iterations``) EM
    iterations.  ``predicted`` (one frame, e.g. :func:`.motion.predict` of the last two poses, usually
    also the start ``pose``) is the target of E_p; without it the start pose is.  ``prior``: joint limits.
    Without a ``camera`` (complete data, e.g. a scan) one step with every model point.
    ``FrameFit.pairs`` is the posterior mass P (observed points the model explains), ``edges`` 0."""
    t0 = time.perf_counter()
    cap = iterations or opts.gmm_iterations
    predicted = pose if predicted is None else predicted
    state = EMState(pose, opts.gmm_sigma ** 2)
    if not obs.empty:
        x = sample(obs, opts.gmm_points)
        for step in ((1, 2) if camera is not None else (1,)):
            state = em(body, x, camera, state, opts, prior, predicted, step, cap)
    posed = state.posed if state.posed is not None else body.pose(state.pose)
    share, mean = coverage(body, posed, obs, opts.near_m)
    return FrameFit(state.pose, state.iterations, int(round(state.mass)), 0, share, mean,
                    time.perf_counter() - t0, posed)
