"""Reaching and bending: smooth random motion with large arm and trunk motion (arms raised above the head,
the trunk bending and twisting, the body turning), for tracking benchmarks.

* Arms: at key frames (every ``key_every`` frames) each upper arm's target direction is drawn relative to
  the trunk's rest axes (world Z up, the subject facing -Y, ``.L`` at +x): elevation uniform in
  [-60, 85] degrees above the horizontal (85: beside the head), azimuth uniform in [15, 110] degrees from
  straight ahead towards the arm's own side (never across the chest).  The upper arm turns onto it by the
  shortest arc from its rest direction, a rotation relative to its parent, so the arm rises with respect
  to the trunk whatever the trunk does; the key rotation vectors are interpolated linearly in between.
* Trunk: at the same keys a bend of [-20, 80] degrees about a horizontal axis [-70, 70] degrees from the
  subject's left-right axis (forward bends, side bends, a little backward) and a twist of [-35, 35] degrees
  about the vertical, the rotation split evenly over the spine bones between the root and the neck that do
  not carry the legs (the same world axis, so they add up exactly).
* Everything else: :func:`.poses.rom_poses` keys at the same spacing with the joint limits scaled per role
  by :data:`REACH_AMPLITUDE` (elbows bend up to about 100 degrees, the legs move little), on top of which
  the upper arms' and spine bones' own small random swing and twist stay.
* Turning: a root yaw uniform in [-turn_degrees, turn_degrees] per key, and a horizontal wander of
  ``root_shift`` metres per axis (``rom_poses``' root motion).  Feet are not kept on the floor.

Deterministic from ``seed``; any rig of :data:`.mpfb_rig.RIGS`.  Angles in degrees, lengths in metres.
"""
from __future__ import annotations

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.geometry.rotations import quat_mul, rotvec_to_quat
from ..solver.rig.model import Poses
from .bone_roles import skeleton_roles
from .poses import _interpolate, rom_poses

#: Per-role factors of the joint limits (``bone_roles.LIMITS``) in the reach motion; roles not listed: 0.3.
REACH_AMPLITUDE = {
    "root": 0.0, "other": 0.0, "spine": 0.4, "neck": 0.6, "head": 0.6, "clavicle": 0.6,
    "upper_arm": 0.25, "forearm": 0.7, "wrist": 0.6, "twist_arm": 0.5, "finger": 0.5,
    "hip_girdle": 0.3, "hip": 0.25, "knee": 0.25, "ankle": 0.25, "toe": 0.3, "twist_leg": 0.3,
}
ELEVATION = (-60.0, 85.0)    # degrees above the horizontal
AZIMUTH = (15.0, 110.0)      # degrees from straight ahead (-Y) towards the arm's side
BEND = (-20.0, 80.0)         # trunk bend, degrees (positive: forwards when the axis is +x)
BEND_AXIS = (-70.0, 70.0)    # bend axis, degrees from +x about the vertical
TWIST = (-35.0, 35.0)        # trunk twist about the vertical, degrees


def arm_directions(rng, K: int, side: float) -> np.ndarray:
    """(K, 3) unit target directions of one upper arm (module docstring); side +1 for ``.L`` (+x), -1 ``.R``."""
    el = np.radians(rng.uniform(*ELEVATION, K))
    az = np.radians(rng.uniform(*AZIMUTH, K))
    return np.stack([side * np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), np.sin(el)], axis=1)


def trunk_rotvecs(rng, K: int) -> np.ndarray:
    """(K, 3) world rotation vectors of the whole trunk's bend and twist at the keys (module docstring)."""
    phi = np.radians(rng.uniform(*BEND_AXIS, K))
    bend = np.radians(rng.uniform(*BEND, K))
    twist = np.radians(rng.uniform(*TWIST, K))
    return np.stack([bend * np.cos(phi), bend * np.sin(phi), twist], axis=1)


def trunk_bones(skeleton, roles) -> list:
    """Spine bones between the root and the first neck bone that carry no leg (no hip below them)."""
    parents = skeleton.parents

    def ancestors(b):
        out = []
        while parents[b] >= 0:
            b = int(parents[b])
            out.append(b)
        return out
    above_neck = ancestors(roles.index("neck"))
    above_legs = {a for b, r in enumerate(roles) if r == "hip" for a in ancestors(b)}
    return [b for b in above_neck if roles[b] == "spine" and b not in above_legs]


def _arc_rotvecs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K, 3) rotation vectors of the shortest arcs taking unit ``a (3,)`` onto unit rows of ``b (K, 3)``."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, b @ a)
    return axis / np.maximum(s, 1e-12)[:, None] * angle[:, None]


def _check(n, key_every, turn_degrees, root_shift):
    if int(n) != n or n < 1:
        raise ArticulaInputError(f"poses: the number of poses must be a positive integer, got {n}")
    if int(key_every) != key_every or key_every < 1:
        raise ArticulaInputError(f"key_every: must be a positive integer, got {key_every}")
    if not 0 <= turn_degrees <= 180:
        raise ArticulaInputError(f"turn_degrees: must be in [0, 180] degrees, got {turn_degrees}")
    if root_shift < 0:
        raise ArticulaInputError(f"root_shift: must be >= 0 metres, got {root_shift}")


def reach_poses(subject, n: int, seed: int = 0, key_every: int = 10, turn_degrees: float = 45.0,
                root_shift: float = 0.1) -> Poses:
    """``n`` poses of ``subject`` (``subjects.Subject``, or anything with a ``skeleton``) reaching, bending
    and turning (module docstring)."""
    _check(n, key_every, turn_degrees, root_shift)
    sk = subject.skeleton
    roles = skeleton_roles(sk.names)
    poses = rom_poses(sk, n, seed=seed, key_every=key_every, root_yaw=turn_degrees, root_shift=root_shift,
                      role_amplitude={r: REACH_AMPLITUDE.get(r, 0.3) for r in set(roles)})
    rng = np.random.default_rng([seed, 1])
    K = (n - 1) // key_every + 2
    rot = poses.rotations.copy()
    trunk = trunk_bones(sk, roles)
    bend = _interpolate(trunk_rotvecs(rng, K), n, key_every) / max(len(trunk), 1)
    for b in trunk:
        rot[:, b] = quat_mul(rotvec_to_quat(bend @ sk.frames[b]), rot[:, b])
    for b, role in enumerate(roles):
        side = {".L": 1.0, ".R": -1.0}.get(sk.names[b][-2:])
        if role != "upper_arm" or side is None:
            continue
        rest = sk.tails[b] - sk.heads[b]
        world = _arc_rotvecs(rest / np.linalg.norm(rest), arm_directions(rng, K, side))
        local = world @ sk.frames[b]                  # F^T r: the same rotation in the bone's rest axes
        rot[:, b] = quat_mul(rotvec_to_quat(_interpolate(local, n, key_every)), rot[:, b])
    return Poses(rot, poses.translations, poses.scales)
