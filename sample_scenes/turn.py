"""Turning on the spot: the subject stands facing the camera (-Y) and turns left and right about the
vertical axis through its root joint while moving its arms and legs.

* Yaw (about world Z, degrees, positive = counter-clockwise seen from above):
  ``yaw(k) = turn_degrees * sin(2 pi k / period)`` at frame k, so it starts at 0, reaches +A at
  period/4 and -A at 3 period/4 (one left-right-left cycle per ``period`` frames; 60 = 2 s at 30 fps).
* Limbs: :func:`.poses.rom_poses` key poses every ``key_every`` frames, linearly interpolated, with the
  joint limits scaled by ``amplitude`` times :data:`TURN_AMPLITUDE` of each role (arms wave and rise to
  about shoulder height, elbows and knees bend moderately, the trunk stays roughly upright).
* Ground contact: each frame is moved vertically so the lowest foot vertex (linear blend skin of the
  vertices bound mostly to the ankle and toe bones) is at z = 0, the subject's rest floor; the other
  foot may lift.  Other skins (dqs, hybrid) put the soles within a few millimetres of that.
* Optional ``root_shift``: a smooth random horizontal wander (metres per axis) as in ``rom_poses``.

Deterministic from ``seed``.  Works for every rig of :data:`.mpfb_rig.RIGS`.
"""
from __future__ import annotations

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.geometry.rotations import quat_mul
from ..solver.rig import skinning
from ..solver.rig.kinematics import forward_kinematics
from ..solver.rig.model import Poses
from .bone_roles import skeleton_roles
from .poses import rom_poses, yaw_quaternions

#: Per-role factors of the joint limits (``bone_roles.LIMITS``) in the turn motion; roles not listed: 0.3.
TURN_AMPLITUDE = {
    "root": 0.0, "other": 0.0, "spine": 0.3, "neck": 0.4, "head": 0.4, "clavicle": 0.5,
    "upper_arm": 0.8, "forearm": 0.6, "wrist": 0.4, "twist_arm": 0.5, "finger": 0.5,
    "hip_girdle": 0.5, "hip": 0.3, "knee": 0.35, "ankle": 0.3, "toe": 0.3, "twist_leg": 0.3,
}
#: Vertices whose linear-blend weights on these roles exceed one half are the feet (ground contact).
FOOT_ROLES = ("ankle", "toe")


def turn_yaw(n: int, turn_degrees: float = 40.0, period: float = 60.0) -> np.ndarray:
    """(n,) yaw angles in radians of frames 0..n-1 (module docstring)."""
    return np.radians(turn_degrees) * np.sin(2 * np.pi * np.arange(n) / period)


def _check(turn_degrees, period, root_yaw):
    if not 0 <= turn_degrees <= 180:
        raise ArticulaInputError(f"turn_degrees: must be in [0, 180] degrees, got {turn_degrees}")
    if not period >= 2:
        raise ArticulaInputError(f"turn_period: must be at least 2 frames, got {period}")
    if root_yaw:
        raise ArticulaInputError("root_yaw: the turn motion sets the yaw itself (use turn_degrees / "
                                 "--turn-degrees instead of root_yaw / --root-yaw)")


def foot_vertices(subject) -> np.ndarray:
    """Ids of the body vertices bound mostly (LBS weight > 0.5) to the ankle and toe bones."""
    roles = np.array(skeleton_roles(subject.skeleton.names))
    on_feet = subject.lbs_weights[:, np.isin(roles, FOOT_ROLES)].sum(axis=1)
    return np.flatnonzero(on_feet > 0.5)


def turn_poses(subject, n: int, seed: int = 0, turn_degrees: float = 40.0, period: float = 60.0,
               amplitude: float = 1.0, key_every: int = 12, root_yaw: float = 0.0,
               root_shift: float = 0.0) -> Poses:
    """``n`` poses of ``subject`` (``subjects.Subject``) turning on the spot (module docstring).

    turn_degrees: yaw amplitude A (degrees); period: frames per left-right-left cycle; amplitude in (0, 1]
    and key_every: the limb motion's limit scale and key spacing (frames); root_yaw must be 0."""
    _check(turn_degrees, period, root_yaw)
    sk = subject.skeleton
    poses = rom_poses(sk, n, seed=seed, amplitude=amplitude, key_every=key_every, root_shift=root_shift,
                      role_amplitude={r: TURN_AMPLITUDE.get(r, 0.3) for r in set(skeleton_roles(sk.names))})
    rot = poses.rotations.copy()
    rot[:, 0] = quat_mul(yaw_quaternions(sk.frames[0], turn_yaw(n, turn_degrees, period)), rot[:, 0])
    turned = Poses(rot, poses.translations, poses.scales)
    feet = foot_vertices(subject)
    Rm, tm = forward_kinematics(sk, turned)
    lowest = skinning.lbs(subject.vertices[feet], subject.lbs_weights[feet], Rm, tm)[..., 2].min(axis=1)
    shift = poses.translations.copy()
    shift[:, 2] -= lowest - subject.vertices[:, 2].min()
    return Poses(rot, shift, poses.scales)
