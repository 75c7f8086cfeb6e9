"""Turning a character's gaze line towards a target, the turn shared by a chain of joints (model-adaptive
mocap, Sec. 4.2.3; spec §7.2 "automatic gaze direction control": breast 10 %, neck 40 %, head 50 %).

Per frame, the total correction is one rotation ``R = Rot(a, φ)`` (axis ``a`` in armature space) that
brings the gaze line (``origin`` + ``direction``, fixed in the head bone) onto the target; joint k of the
chain turns by ``Rot(a, s_k φ)`` (shares ``s_k``) about its own centre, applied to its pose bone as
``L_k ← P_kᵀ Rot(a, s_k φ) P_k L_k`` with ``P_k`` its parent's (rest-relative) pose rotation.  All turns
share the axis, so the head turns by exactly φ; because the joints' centres differ the gaze origin moves a
little, so ``R`` is refined a few times (``R ← Rot(d → g) · R``).  The angle is limited by every joint's
largest turn ``max_k / s_k`` (the frames where that bites are reported), then scaled by the frame's fade
weight.  Array conventions: :mod:`solver.retarget.armature` (``F`` frames, ``J`` bones, armature space).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import quat_to_rotvec, matrix_to_quat, rotation_between, rotvec_to_matrix
from ..retarget.armature import ArmatureRest, forward

ITERATIONS = 5


@dataclass
class GazeChain:
    joints: list             # bone indices of the turning joints, top-down (chest, neck, head)
    shares: np.ndarray       # (K,) their shares of the turn, summing to 1
    head: int                # the bone that carries the gaze line
    origin: np.ndarray       # (3,) gaze origin in the head bone's rest-local axes (armature units)
    direction: np.ndarray    # (3,) unit gaze direction in the head bone's rest-local axes
    max_angles: np.ndarray   # (K,) each joint's largest turn (radians)

    def check(self, arm: ArmatureRest) -> None:
        shares = np.asarray(self.shares, dtype=np.float64)
        if len(shares) != len(self.joints) or len(shares) == 0:
            raise ArticulaInputError("gaze: one share per turning joint is needed")
        if np.any(shares < 0) or abs(shares.sum() - 1.0) > 1e-6:
            raise ArticulaInputError(f"gaze: the shares must be >= 0 and sum to 1 (got {shares.tolist()})")
        for upper, j in zip(self.joints, self.joints[1:]):
            if upper == j or not arm.is_ancestor(upper, j):
                raise ArticulaInputError(f"gaze: {arm.bones[j]!r} does not hang from {arm.bones[upper]!r}")

    @property
    def reach(self) -> float:
        """Largest total turn (radians) the joints allow together."""
        s = np.asarray(self.shares, dtype=np.float64)
        return float(np.min(np.where(s > 0, np.asarray(self.max_angles) / np.maximum(s, 1e-12), np.inf)))


def gaze_line(arm: ArmatureRest, pose: np.ndarray, chain: GazeChain):
    """Gaze origins ``(F, 3)`` and unit directions ``(F, 3)`` in armature space of pose matrices ``pose``."""
    M = pose[:, chain.head]
    p = np.einsum("fij,j->fi", M[:, :3, :3], chain.origin) + M[:, :3, 3]
    d = np.einsum("fij,j->fi", M[:, :3, :3], chain.direction)
    return p, d / np.linalg.norm(d, axis=1, keepdims=True)


def turn(arm: ArmatureRest, local: np.ndarray, pose: np.ndarray, chain: GazeChain, rotvec: np.ndarray) -> np.ndarray:
    """Pose-bone matrices ``local (F, J, 4, 4)`` with the chain turned by the armature-space rotation
    vectors ``rotvec (F, 3)`` split by the shares (``pose``: the unturned pose of ``local``)."""
    rel = arm.relative_rest()
    out = local.copy()
    for j, share in zip(chain.joints, chain.shares):
        p = arm.parents[j]
        P = rel[j][None, :3, :3] if p < 0 else pose[:, p, :3, :3] @ rel[j][:3, :3]
        D = rotvec_to_matrix(share * rotvec)
        out[:, j, :3, :3] = np.swapaxes(P, 1, 2) @ D @ P @ local[:, j, :3, :3]
    return out


def solve(arm: ArmatureRest, local: np.ndarray, chain: GazeChain, targets: np.ndarray, weights: np.ndarray):
    """``(local', report)``: pose-bone matrices ``local (F, J, 4, 4)`` turned so the gaze meets
    ``targets (F, 3)`` (armature space) with strength ``weights (F,)``; frames of weight 0 are untouched."""
    chain.check(arm)
    pose = forward(arm, local)
    total = np.zeros((len(local), 3))
    for _ in range(ITERATIONS):
        p, d = gaze_line(arm, forward(arm, turn(arm, local, pose, chain, total)), chain)
        g = targets - p
        near = np.linalg.norm(g, axis=1) < 1e-9
        g = np.where(near[:, None], d, g) / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
        R = rotation_between(d, g) @ rotvec_to_matrix(total)
        total = quat_to_rotvec(matrix_to_quat(R))
    angle = np.linalg.norm(total, axis=1)
    limited = angle > chain.reach
    total[limited] *= (chain.reach / angle[limited])[:, None]
    w = np.asarray(weights, dtype=np.float64)
    out = turn(arm, local, pose, chain, total * w[:, None])
    out[w == 0] = local[w == 0]
    p, d = gaze_line(arm, forward(arm, out), chain)
    g = targets - p
    err = np.degrees(np.arccos(np.clip(np.einsum("fi,fi->f", d, g) / np.maximum(np.linalg.norm(g, axis=1), 1e-12),
                                       -1.0, 1.0)))
    report = {"turn_deg": np.degrees(angle), "limited": np.flatnonzero(limited & (w > 0)),
              "error_deg": err, "reach_deg": np.degrees(chain.reach)}
    return out, report


def aim_eyes(arm: ArmatureRest, local: np.ndarray, eyes, targets: np.ndarray, weights: np.ndarray,
             max_angle: float = np.radians(30.0)):
    """Pose-bone matrices with each eye of ``eyes`` — ``[(bone, direction (3,) in its rest-local axes)]`` —
    turned about its centre to look at ``targets (F, 3)`` (both eyes converge), by at most ``max_angle``,
    scaled by ``weights (F,)``; returns ``(local', limited frames)``."""
    out = local.copy()
    limited = np.zeros(len(local), bool)
    pose = forward(arm, local)
    rel = arm.relative_rest()
    w = np.asarray(weights, dtype=np.float64)
    for bone, direction in eyes:
        M = pose[:, bone]
        d = M[:, :3, :3] @ direction
        g = targets - M[:, :3, 3]
        R = rotation_between(d / np.linalg.norm(d, axis=1, keepdims=True),
                             g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12))
        rv = quat_to_rotvec(matrix_to_quat(R))
        angle = np.linalg.norm(rv, axis=1)
        over = angle > max_angle
        limited |= over & (w > 0)
        rv[over] *= (max_angle / angle[over])[:, None]
        p = arm.parents[bone]
        P = rel[bone][None, :3, :3] if p < 0 else pose[:, p, :3, :3] @ rel[bone][:3, :3]
        D = rotvec_to_matrix(rv * w[:, None])
        out[:, bone, :3, :3] = np.swapaxes(P, 1, 2) @ D @ P @ local[:, bone, :3, :3]
    out[w == 0] = local[w == 0]
    return out, np.flatnonzero(limited)
