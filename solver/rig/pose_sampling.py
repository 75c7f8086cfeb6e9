"""Random poses over a joint's range of motion, for measuring a rig where no animation says which poses
matter (e.g. how far the linear-blend version of a rig departs from the exact swing/twist rig,
``linear_blend.deviation``).  Seeded, so a measurement can be repeated.

A pose is :class:`~.model.Poses`: every non-root bone turns by a swing (about a random axis in its local
XZ plane) followed by a twist about its local Y axis, as the rig decomposes rotations (``rotations``
module, Y = twist axis); the root gets a uniformly random rotation, a translation and a scale.
"""
import numpy as np

from ..geometry.rotations import quat_mul
from .model import Poses


def swing_twist_rotations(rng, n: int, num_bones: int, max_twist_deg: float = 170.0,
                          max_swing_deg: float = 110.0) -> np.ndarray:
    """``(n, num_bones, 4)`` unit quaternions: per bone swing·twist with the twist angle uniform in
    ±``max_twist_deg`` and the swing angle uniform in [0, ``max_swing_deg``] (degrees), about an axis at
    a uniform angle in the bone's XZ plane; bone 0 (the root) uniformly random on the sphere of unit
    quaternions.  Draws from ``rng`` (a numpy Generator) in this order: twist, swing, swing axis, root."""
    twist = np.radians(rng.uniform(-max_twist_deg, max_twist_deg, (n, num_bones)))
    swing = np.radians(rng.uniform(0, max_swing_deg, (n, num_bones)))
    phi = rng.uniform(0, 2 * np.pi, (n, num_bones))
    zero = np.zeros_like(twist)
    q_twist = np.stack([np.cos(twist / 2), zero, np.sin(twist / 2), zero], -1)
    s = np.sin(swing / 2)
    q_swing = np.stack([np.cos(swing / 2), s * np.cos(phi), zero, s * np.sin(phi)], -1)
    q = quat_mul(q_swing, q_twist)
    root = rng.normal(size=(n, 4))
    q[:, 0] = root / np.linalg.norm(root, axis=1, keepdims=True)
    return q


def random_poses(n: int, num_bones: int, seed: int = 0, max_twist_deg: float = 170.0,
                 max_swing_deg: float = 110.0) -> Poses:
    """``n`` poses of :func:`swing_twist_rotations` with the root translated uniformly within ±0.5 m
    per axis and scaled uniformly in [0.7, 1.4], from ``numpy.random.default_rng(seed)``."""
    rng = np.random.default_rng(seed)
    q = swing_twist_rotations(rng, n, num_bones, max_twist_deg, max_swing_deg)
    return Poses(q, rng.uniform(-0.5, 0.5, (n, 3)), rng.uniform(0.7, 1.4, n))
