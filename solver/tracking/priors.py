"""Priors of a frame fit, as terms with the interface of :mod:`.terms` (``energy``/``linearise``).

* :class:`TowardPose`: a quadratic pull of the frame's parameters towards a target pose (the previous
  pose, or its constant-velocity prediction) with a full ``(P, P)`` weight; the weight is chosen by
  :func:`weak_directions` so that only the directions the data barely constrain (the neck against the
  head, an arm's twist: small eigenvalues of the data's normal matrix) are held, and the rest move
  freely.  Residual: ``[t - t*; log(q*_b^-1 q_b)]`` with its exact increment Jacobian.
* :class:`PairPrior`: the pairwise Gaussian-mixture pose prior (model-adaptive mocap dissertation §4.1.3,
  Eq. 4.7-4.8) of :class:`solver.track.pose_prior.PosePrior`, weighted.
* :class:`JointBox`: a quadratic penalty beyond per-joint box limits of the rotation vectors (§4.1.4;
  soft instead of the active set, so one solver serves every term).
"""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import quat_conj, quat_mul, quat_to_rotvec
from .pose_prior import rotvec_increment_jacobian
from .terms import Linear


def pose_difference(pose, target):
    """``(e (P,), Je (P, P))``: translation difference and per-bone ``log(q*^-1 q)`` of one frame, with
    the derivative by the frame's parameters (:class:`.body.Body` layout)."""
    rel = quat_mul(quat_conj(target.rotations[0]), pose.rotations[0])
    rel = np.where(rel[:, :1] < 0, -rel, rel)                          # the short way round
    r = quat_to_rotvec(rel)
    B = len(r)
    Je = np.zeros((3 + 3 * B, 3 + 3 * B))
    Je[:3, :3] = np.eye(3)
    blocks = rotvec_increment_jacobian(r)
    for b in range(B):
        Je[3 + 3 * b:6 + 3 * b, 3 + 3 * b:6 + 3 * b] = blocks[b]
    return np.concatenate([pose.translations[0] - target.translations[0], r.ravel()]), Je


class TowardPose:
    """``1/2 e^T W e`` with ``e`` = :func:`pose_difference` to ``target``; ``W (P, P)`` symmetric PSD."""

    def __init__(self, target, W):
        self.target, self.W = target, W

    def energy(self, body, state) -> float:
        pose = state.pose
        e, _ = pose_difference(pose, self.target)
        return 0.5 * float(e @ self.W @ e)

    def linearise(self, body, state) -> Linear:
        pose = state.pose
        e, Je = pose_difference(pose, self.target)
        WJ = self.W @ Je
        return Linear(Je.T @ WJ, Je.T @ (self.W @ e), 0.5 * float(e @ self.W @ e))


def weak_directions(H, ratio: float = 1e-3, floor: float = 0.0) -> np.ndarray:
    """``(P, P)`` weight lifting every eigenvalue of the data's normal matrix ``H`` to at least
    ``ratio`` times its largest (plus ``floor`` everywhere): directions the data constrain well get
    (almost) nothing, the unconstrained ones a pull of the size of a weakly seen part."""
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    lift = np.maximum(ratio * max(lam[-1], 0.0) - lam, 0.0) + floor
    return (V * lift) @ V.T


class PairPrior:
    """``weight * 1/2 sum_p e_p^2`` of a :class:`PosePrior` (Eq. 4.8's residuals ``e_p``)."""

    def __init__(self, prior, weight: float):
        self.prior, self.weight = prior, weight

    def _residuals(self, pose):
        return self.prior.residuals(pose.rotations)[0]

    def energy(self, body, state) -> float:
        pose = state.pose
        e = self._residuals(pose)
        return 0.5 * self.weight * float(e @ e)

    def linearise(self, body, state) -> Linear:
        pose = state.pose
        e = self._residuals(pose)
        J = self.prior.jacobian(pose.rotations)[0][:, body.columns]
        return Linear(self.weight * (J.T @ J), self.weight * (J.T @ e), 0.5 * self.weight * float(e @ e))


class JointBox:
    """``weight * 1/2 sum (r - clip(r, lower, upper))^2`` over the bones' rotation vectors ``r = log q``
    (radians); lower, upper ``(B, 3)`` (+-inf: free); bone 0 (the root) is never limited."""

    def __init__(self, lower, upper, weight: float):
        self.lower, self.upper, self.weight = np.asarray(lower, float), np.asarray(upper, float), weight
        self.lower[0], self.upper[0] = -np.inf, np.inf

    def _excess(self, pose):
        r = quat_to_rotvec(pose.rotations[0])
        return r, r - np.clip(r, self.lower, self.upper)

    def energy(self, body, state) -> float:
        pose = state.pose
        _, x = self._excess(pose)
        return 0.5 * self.weight * float(np.sum(x * x))

    def linearise(self, body, state) -> Linear:
        pose = state.pose
        r, x = self._excess(pose)
        P = body.size
        J = np.zeros((len(r), 3, P))
        blocks = rotvec_increment_jacobian(r)
        for b in range(len(r)):
            J[b, :, 3 + 3 * b:6 + 3 * b] = blocks[b]
        active = (x != 0).ravel()
        J = J.reshape(-1, P)[active]
        e = x.ravel()[active]
        return Linear(self.weight * (J.T @ J), self.weight * (J.T @ e), 0.5 * self.weight * float(e @ e))
