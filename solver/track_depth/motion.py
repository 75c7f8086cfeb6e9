"""Prediction of the next frame's pose from the last tracked ones (the motion model the depth-camera
tracking dissertation suggests against fast limbs, ch. 5 §5.5, and the prediction of ch. 6 Eq. 6.13):
each joint keeps turning, and the root keeps moving, by ``gain`` times its last frame-to-frame change."""
from __future__ import annotations

from ..geometry.rotations import (quat_canonical, quat_conj, quat_mul, quat_normalize, quat_to_rotvec,
                                  rotvec_to_quat)
from ..rig.model import Poses

GAIN = 0.8   # share of the last change carried on (1 = constant velocity; less damps overshoot at stops)


def _power(q, t: float):
    """Unit quaternions (..., 4) raised to the real power ``t`` (same axis, t times the angle)."""
    return rotvec_to_quat(t * quat_to_rotvec(quat_canonical(q)))


def predict(previous: Poses, last: Poses, gain: float = GAIN) -> Poses:
    """One frame extrapolated from two consecutive ones (each (1, B, 4) rotations): local rotations
    ``q_last (q_prev^-1 q_last)^gain``, translation ``t_last + gain (t_last - t_prev)``."""
    step = quat_mul(quat_conj(previous.rotations), last.rotations)
    rot = quat_normalize(quat_mul(last.rotations, _power(step, gain)))
    trans = last.translations + gain * (last.translations - previous.translations)
    return Poses(rot, trans, last.scales.copy())
