"""Initial per-scan poses from per-part rigid fits (dissertation (model-adaptive mocap) §3.2 step 6).

Part b's chain map is ``M_b = M_parent ∘ Rot(R_b about heads[b])`` so its linear part is
``W_b = W_parent R_b``: the world-axes joint rotation is ``R_b = W_parentᵀ W_b`` and the bone-local
quaternion (the bundle's ``pose_rotations``) is that of ``F_bᵀ R_b F_b``.  The root map is
``W_0 (x − h_0) + h_0 + t`` so ``t = τ_0 − h_0 + W_0 h_0``; the other Procrustes translations are
dropped (the chain recreates them from the joint centres).  Scale is 1.
"""
import numpy as np

from ..rig.model import Poses
from ..geometry.rotations import matrix_to_quat


def poses_from_part_fits(skeleton, W, tau):
    """Poses from per-bone rigid fits.

    skeleton: the learned :class:`Skeleton`; W ``(M,B,3,3)``, tau ``(M,B,3)``: the rigid map of every
    bone's part in every scan (bone order, i.e. already permuted from part order).
    Returns :class:`Poses` with ``rotations (M,B,4)`` (w >= 0), ``translations (M,3)``, ``scales = 1``."""
    W = np.asarray(W, dtype=np.float64)
    par = np.maximum(skeleton.parents, 0)
    R = np.swapaxes(W[:, par], -1, -2) @ W                       # W_parentᵀ W_b
    R[:, 0] = W[:, 0]
    F = skeleton.frames
    local = np.swapaxes(F, -1, -2) @ R @ F
    h0 = skeleton.heads[0]
    t = tau[:, 0] - h0 + W[:, 0] @ h0
    return Poses(matrix_to_quat(local), t, np.ones(len(W)))
