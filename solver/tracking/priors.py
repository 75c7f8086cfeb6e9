"""Priors of a frame fit, as terms with the interface of :mod:`.terms` (``energy``/``linearise``).

* :class:`TowardPose`: a quadratic pull of the frame's parameters towards a target pose (the previous
  pose, or its constant-velocity prediction) with a full ``(P, P)`` weight; the weight is chosen by
  :func:`weak_directions` so that only the directions the data barely constrain (the neck against the
  head, an arm's twist: small eigenvalues of the data's normal matrix) are held, and the rest move
  freely.  Residual: ``[t - t*; log(q*_b^-1 q_b)]`` with its exact increment Jacobian.
* :class:`PairPrior`: the pairwise Gaussian-mixture pose prior (model-adaptive mocap dissertation §4.1.3,
  Eq. 4.7-4.8) of :class:`solver.track.pose_prior.PosePrior`, weighted.
* :class:`JointBox`: a quadratic penalty beyond per-joint box limits of the rotation vectors (§4.1.4;
  soft instead of the active set, so one solver serves every term), with an optional weak pull to the
  boxes' middles; :func:`generic_limits` the generic human prior's boxes (ours: the depth-camera
  dissertation's trackers have none, ch. 5 §5.5 names the drift of weakly seen joints as a failure).

Every prior works on any body with the parameters of :class:`.body.Body` (``body.size``,
``body.columns``), the exact one or :class:`.blend_body.BlendBody`; it reads only ``state.pose``.
"""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import quat_conj, quat_mul, quat_to_rotvec
from .pose_prior import generic_prior, rotvec_increment_jacobian
from .terms import Linear, bone_columns

BOX_WEIGHT = 10.0           # generic limits: m^2 per rad^2 outside the box (against unit point rows)
CENTRE_WEIGHT = 0.02        # ... m^2 per (box width)^2 away from its middle
HOLD_WEIGHT = 1000.0        # m^2 per rad^2 away from a held rotation
MIN_WIDTH = np.radians(5.0)  # narrower boxes pull to their middle as this wide


def pose_difference(pose, target):
    """``(e (P,), Je (P, P))``: translation difference and per-bone ``log(q*^-1 q)`` of one frame, with
    the derivative by the frame's parameters (:class:`.body.Body` layout)."""
    e, blocks = _difference(pose, target)
    B = len(blocks)
    Je = np.zeros((3 + 3 * B, 3 + 3 * B))
    Je[:3, :3] = np.eye(3)
    cols = bone_columns(np.arange(B))
    Je[cols[:, :, None], cols[:, None, :]] = blocks
    return e, Je


def _difference(pose, target):
    """``e (P,)`` of :func:`pose_difference` and its bones' diagonal blocks ``(B, 3, 3)``."""
    rel = quat_mul(quat_conj(target.rotations[0]), pose.rotations[0])
    rel = np.where(rel[:, :1] < 0, -rel, rel)                          # the short way round
    r = quat_to_rotvec(rel)
    return np.concatenate([pose.translations[0] - target.translations[0], r.ravel()]), rotvec_increment_jacobian(r)


class TowardPose:
    """``1/2 e^T W e`` with ``e`` = :func:`pose_difference` to ``target``; ``W (P, P)`` symmetric PSD, or
    ``(P,)`` its diagonal (a per-parameter pull, :func:`toward_bones`), summed block by block."""

    def __init__(self, target, W):
        self.target, self.W = target, np.asarray(W, dtype=float)

    def energy(self, body, state) -> float:
        e, _ = _difference(state.pose, self.target)
        return 0.5 * float(self.W @ (e * e)) if self.W.ndim == 1 else 0.5 * float(e @ self.W @ e)

    def linearise(self, body, state) -> Linear:
        pose = state.pose
        if self.W.ndim == 1:
            return self._diagonal(pose)
        e, Je = pose_difference(pose, self.target)
        WJ = self.W @ Je
        return Linear(Je.T @ WJ, Je.T @ (self.W @ e), 0.5 * float(e @ self.W @ e))

    def _diagonal(self, pose) -> Linear:
        e, blocks = _difference(pose, self.target)
        w = self.W
        P, B = len(e), len(blocks)
        H, g = np.zeros((P, P)), np.zeros(P)
        H[:3, :3], g[:3] = np.diag(w[:3]), w[:3] * e[:3]
        wb, eb = w[3:].reshape(B, 3), e[3:].reshape(B, 3)
        cols = bone_columns(np.arange(B))
        H[cols[:, :, None], cols[:, None, :]] = np.swapaxes(blocks, 1, 2) @ (blocks * wb[:, :, None])
        g[cols] = np.einsum("bri,br->bi", blocks, wb * eb)
        return Linear(H, g, 0.5 * float(w @ (e * e)))


def toward_bones(target, size: int, bones, weight: float) -> TowardPose:
    """A :class:`TowardPose` on ``bones``' rotations alone (``size`` parameters), each row adding ``weight
    J^T J``: the small parts held at their start, the GMM tracker's E_p."""
    w = np.zeros(size)
    w[bone_columns(bones).ravel()] = weight
    return TowardPose(target, w)


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
    """Soft box limits on the bones' rotation vectors ``r = log q`` (radians, bone-local axes):
    ``weight * 1/2 sum (r - clip(r, lower, upper))^2`` plus ``centre_weight * 1/2 sum ((r - centre) /
    width)^2``, a weak pull to the middle of each box scaled by its width (floored at ``MIN_WIDTH``), so
    joints the data hardly see (hip girdle, clavicles, spine segments) do not wander while a limb's wide
    range is barely pulled.  ``lower``, ``upper`` ``(B, 3)`` (+-inf: free); the root (bone 0) and bones
    without a finite box are never limited.  ``lower == upper`` holds a bone at a rotation."""

    def __init__(self, lower, upper, weight: float, centre_weight: float = 0.0):
        self.lower, self.upper = np.array(lower, dtype=float), np.array(upper, dtype=float)
        self.lower[0], self.upper[0] = -np.inf, np.inf
        self.weight, self.centre_weight = weight, centre_weight
        self.bones = np.flatnonzero(np.isfinite(self.lower).all(axis=1) & np.isfinite(self.upper).all(axis=1))
        lo, hi = self.lower[self.bones], self.upper[self.bones]
        self.centre, self.width = 0.5 * (lo + hi), np.maximum(hi - lo, MIN_WIDTH)

    def _rows(self, pose):
        """Residual blocks ``(k, 3)`` of the limited bones: beyond the box, and the scaled pull."""
        r = quat_to_rotvec(pose.rotations[0, self.bones])
        return r, r - np.clip(r, self.lower[self.bones], self.upper[self.bones]), (r - self.centre) / self.width

    def energy(self, body, state) -> float:
        return self._energy(*self._rows(state.pose)[1:])

    def _energy(self, over, pull) -> float:
        return 0.5 * (self.weight * float(np.sum(over * over)) + self.centre_weight * float(np.sum(pull * pull)))

    def linearise(self, body, state) -> Linear:
        r, over, pull = self._rows(state.pose)
        P = body.size
        H, g = np.zeros((P, P)), np.zeros(P)
        D = rotvec_increment_jacobian(r)                                  # (k, 3, 3) d log(q exp d) / d d
        cols = bone_columns(self.bones)
        w = np.where(over != 0, self.weight, 0.0)
        DD = np.swapaxes(D, 1, 2) @ (D * w[:, :, None])
        DDc = np.swapaxes(D, 1, 2) @ (D * (self.centre_weight / self.width ** 2)[:, :, None])
        H[cols[:, :, None], cols[:, None, :]] += DD + DDc
        g[cols] += np.einsum("kri,kr->ki", D, w * over + self.centre_weight * pull / self.width)
        return Linear(H, g, self._energy(over, pull))



def held_at(num_bones: int, bones, targets) -> JointBox:
    """A box holding ``bones`` at the bone-local rotation vectors ``targets`` (k, 3) by ``HOLD_WEIGHT``
    (body parts out of a camera's view); the others free."""
    lower = np.full((num_bones, 3), np.inf)
    lower[np.asarray(bones, dtype=np.int64)] = targets
    return JointBox(lower, lower, HOLD_WEIGHT)


def generic_limits(skeleton) -> JointBox:
    """Box limits from the generic human prior mapped by bone names (:func:`.pose_prior.generic_prior`)
    with its weak pull to the middle of each box (``BOX_WEIGHT``, ``CENTRE_WEIGHT``)."""
    prior = generic_prior(skeleton)
    return JointBox(prior.lower, prior.upper, BOX_WEIGHT, CENTRE_WEIGHT)
