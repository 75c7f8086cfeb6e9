"""The next frame's pose predicted from the last two (both trackers): each joint keeps turning, and the
root keeps moving, by ``carry`` times its last frame-to-frame change (1: constant velocity; less damps the
overshoot where a motion stops).  The depth-camera tracking dissertation suggests such a motion model
against fast limbs (ch. 5 §5.5) and pulls the GMM fit towards it (ch. 6 Eq. 6.13)."""
from __future__ import annotations

from ..geometry.rotations import quat_conj, quat_mul, quat_normalize, quat_to_rotvec, rotvec_to_quat
from ..rig.model import Poses


def extrapolate(previous: Poses, last: Poses, carry: float = 1.0) -> Poses:
    """One frame extrapolated from two consecutive ones (each (1, B, 4) rotations): local rotations
    ``q_last (q_prev^-1 q_last)^carry`` (the change taken the shorter way round), translation
    ``t_last + carry (t_last - t_prev)``."""
    turn = quat_mul(quat_conj(previous.rotations), last.rotations)
    if carry != 1.0:
        turn = rotvec_to_quat(carry * quat_to_rotvec(turn))
    rot = quat_normalize(quat_mul(last.rotations, turn))
    return Poses(rot, last.translations + carry * (last.translations - previous.translations), last.scales.copy())
