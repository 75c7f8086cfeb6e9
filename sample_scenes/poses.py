"""Random range-of-motion poses within per-joint limits (deterministic from a seed).

Per bone the pose is parameterised by a swing rotation vector ``s`` in the bone's local XZ plane and a
twist angle ``t`` about local Y; the rotation relative to rest is ``q = q(s) * q_twist(t)`` (w, x, y, z),
in bone-local axes as Blender's pose-bone quaternion (``solver.rig.model.Poses``).  Limits come from
:mod:`.bone_roles`: ball joints draw ``s`` uniformly from the disk ``|s| <= cone`` and ``t`` uniformly
from ``[-twist, twist]``; hinges (elbow, knee) draw the flexion angle uniformly from the rest-relative range
(:func:`.bone_roles.hinge_ranges`) and rotate about the anatomical hinge axis
(:func:`.bone_roles.hinge_geometry`).  ``amplitude`` in (0, 1] scales every limit (hinge ranges are
scaled about the rest pose, so they always contain it), ``role_amplitude`` some roles' limits further.

``key_every = k > 1`` draws key poses every k frames and interpolates the parameters linearly in
between, which gives a smooth motion that stays within the limits (the disk and the intervals are
convex).  Root motion (optional): a yaw about world Z through the root joint, uniform in
``[-root_yaw, root_yaw]`` degrees, and a horizontal translation uniform in ``[-root_shift, root_shift]``
metres per axis.  Scales are 1.
"""
from __future__ import annotations

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.rig.model import Poses
from ..solver.geometry.rotations import matrix_to_quat, quat_mul, rotvec_to_quat
from .bone_roles import LIMITS, hinge_geometry, hinge_ranges, skeleton_roles


def _check(n, amplitude, key_every, root_yaw, root_shift, role_amplitude):
    if int(n) != n or n < 1:
        raise ArticulaInputError(f"poses: the number of poses must be a positive integer, got {n}")
    if not 0 < amplitude <= 1:
        raise ArticulaInputError(f"amplitude: must be in (0, 1], got {amplitude}")
    for role, factor in (role_amplitude or {}).items():
        if role not in LIMITS or not 0 <= factor <= 1:
            raise ArticulaInputError(f"role_amplitude: {role!r}: {factor} must be a role of bone_roles.LIMITS "
                                     f"with a factor in [0, 1]")
    if int(key_every) != key_every or key_every < 1:
        raise ArticulaInputError(f"key_every: must be a positive integer, got {key_every}")
    if not 0 <= root_yaw <= 180:
        raise ArticulaInputError(f"root_yaw: must be in [0, 180] degrees, got {root_yaw}")
    if root_shift < 0:
        raise ArticulaInputError(f"root_shift: must be >= 0 metres, got {root_shift}")


def limit_arrays(skeleton, roles, amplitude=1.0):
    """cone, twist (B,) radians; rest-relative hinge ranges (B, 2) radians (NaN for ball joints),
    all scaled by ``amplitude`` (a number or one per bone, (B,)) about the rest pose."""
    lim = [LIMITS[r] for r in roles]
    amplitude = np.asarray(amplitude, dtype=float)
    cone = np.radians([l.cone for l in lim]) * amplitude
    twist = np.radians([l.twist for l in lim]) * amplitude
    return cone, twist, hinge_ranges(skeleton, roles) * amplitude[..., None]


def _draw_keys(rng, K, skeleton, roles, amplitude):
    """Key parameters: swing rotation vectors (K, B, 3) local, twist angles (K, B)."""
    B = len(roles)
    cone, twist, hinge = limit_arrays(skeleton, roles, amplitude)
    alpha = rng.uniform(0, 2 * np.pi, (K, B))
    radius = cone * np.sqrt(rng.uniform(0, 1, (K, B)))
    swing = np.stack([radius * np.cos(alpha), np.zeros((K, B)), radius * np.sin(alpha)], axis=-1)
    is_hinge = ~np.isnan(hinge[:, 0])
    flex = rng.uniform(np.nan_to_num(hinge[:, 0]), np.nan_to_num(hinge[:, 1]), (K, B))
    axes, _ = hinge_geometry(skeleton, roles)
    swing[:, is_hinge] = flex[:, is_hinge, None] * axes[is_hinge]
    tw = rng.uniform(-1, 1, (K, B)) * twist
    return swing, tw


def _interpolate(keys, n, key_every):
    """Linear interpolation of key arrays (K, ...) at frames 0..n-1 (key k at frame k*key_every)."""
    pos = np.arange(n) / key_every
    k0 = np.floor(pos).astype(int)
    f = (pos - k0).reshape((n,) + (1,) * (keys.ndim - 1))
    k1 = np.minimum(k0 + 1, len(keys) - 1)
    return (1 - f) * keys[k0] + f * keys[k1]


def compose_swing_twist(swing: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions ``q(swing rotation vector (..., 3)) * q(twist angle (...) about Y)``."""
    tw = np.zeros(twist.shape + (3,))
    tw[..., 1] = twist
    return quat_mul(rotvec_to_quat(swing), rotvec_to_quat(tw))


def _root_motion(rng, K, root_yaw, root_shift):
    """Key root yaw angles (K,) radians and translations (K, 3) metres."""
    yaw = np.radians(rng.uniform(-root_yaw, root_yaw, K))
    shift = rng.uniform(-1, 1, (K, 3)) * root_shift
    shift[:, 2] = 0.0
    return yaw, shift


def rom_poses(skeleton, n: int, seed: int = 0, amplitude: float = 1.0, key_every: int = 1,
              root_yaw: float = 0.0, root_shift: float = 0.0, role_amplitude: dict | None = None) -> Poses:
    """``n`` random range-of-motion poses of ``skeleton`` (see the module docstring).

    role_amplitude: optional ``{role: factor in [0, 1]}`` multiplying ``amplitude`` for the bones of
    that role (roles not listed: 1).  The random draws do not depend on the amplitudes."""
    _check(n, amplitude, key_every, root_yaw, root_shift, role_amplitude)
    rng = np.random.default_rng(seed)
    roles = skeleton_roles(skeleton.names)
    K = (n - 1) // key_every + 2
    scale = amplitude * np.array([(role_amplitude or {}).get(r, 1.0) for r in roles])
    swing, twist = _draw_keys(rng, K, skeleton, roles, scale)
    yaw, shift = _root_motion(rng, K, root_yaw, root_shift)
    rot = compose_swing_twist(_interpolate(swing, n, key_every), _interpolate(twist, n, key_every))
    rot[:, 0] = quat_mul(yaw_quaternions(skeleton.frames[0], _interpolate(yaw, n, key_every)), rot[:, 0])
    return Poses(rot, _interpolate(shift, n, key_every), np.ones(n))


def yaw_quaternions(frame0: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 4) root-local quaternions of rotations by ``yaw`` (N,) radians about world Z.

    frame0 (3, 3): the root's rest frame; local rotation = F0^T Rz F0."""
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.zeros((len(yaw), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    return matrix_to_quat(frame0.T @ Rz @ frame0)
