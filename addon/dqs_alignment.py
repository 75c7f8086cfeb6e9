"""Where Blender's "Preserve Volume" blend can differ from the solver's twist stage (pure numpy).

Blender's Armature modifier blends dual quaternions in the order of a vertex's vertex-group entries and
flips each bone's quaternion when its dot product with the running sum is negative.  The solver's
hybrid skin aligns every twist quaternion to the neutral (identity) instead.  The rig writes NEUTRAL
first, so the two agree unless, later in the sum, a twist quaternion points away from the running sum.
That needs two twist joints of one vertex with |θ_i| + |θ_j| > 180° (their quaternions' dot product
is at least cos((|θ_i| + |θ_j|)/2)), so it never happens for one twisting joint per vertex or for
human twist ranges, but it does for large opposing twists at a fork.
"""
import numpy as np

from ..solver.rotations import quat_canonical, quat_normalize, swing_twist_y


def world_twist_quats(skeleton, rotations) -> np.ndarray:
    """Rotation quaternions ``(N, B, 4)`` (w >= 0) of the world-axes twists of every bone."""
    _, q_tw = swing_twist_y(quat_canonical(quat_normalize(np.asarray(rotations, dtype=np.float64))))
    axis = skeleton.frames[:, :, 1]
    return np.concatenate([q_tw[..., :1], q_tw[..., 2:3] * axis], axis=-1)


def blender_twist_flips(model, poses) -> np.ndarray:
    """``(N, V)`` bool: True where Blender aligns a vertex's twist blend differently from the solver
    (flips a quaternion against the running sum), with entries in the rig's order: NEUTRAL, then the
    twist bones in bundle order.  All False means Blender reproduces the twist stage exactly."""
    w = np.asarray(model.twist_weights, dtype=np.float32)
    out = np.zeros((len(poses), len(w)), dtype=bool)
    rows = np.flatnonzero((w != 0).sum(axis=1) >= 2)
    if len(rows) == 0:
        return out
    w = w[rows]
    neutral = (np.float32(1.0) - w.astype(np.float64).sum(axis=1)).astype(np.float32).astype(np.float64)
    K = int((w != 0).sum(axis=1).max())
    idx = np.argsort(w == 0, axis=1, kind="stable")[:, :K]             # non-zeros first, ascending bone
    wk = np.take_along_axis(w, idx, axis=1).astype(np.float64)
    Q = world_twist_quats(model.skeleton, poses.rotations)             # (N, B, 4)
    total = np.zeros((len(poses), len(rows), 4))
    total[..., 0] = np.maximum(neutral, 0.0)
    flipped = np.zeros((len(poses), len(rows)), dtype=bool)
    for k in range(K):
        q = Q[:, idx[:, k]]                                            # (N, R, 4)
        active = wk[:, k] > 0
        flip = (np.einsum("nri,nri->nr", q, total) < 0) & active
        total += np.where(flip, -1.0, 1.0)[..., None] * wk[:, k, None] * q
        flipped |= flip
    out[:, rows] = flipped
    return out
