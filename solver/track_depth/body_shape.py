"""The template's overall shape fitted to the person from its MakeHuman macro basis (gender, age,
muscle, weight, height, proportions; :mod:`.template`): with the pose's world rotations fixed the posed
points are linear in the basis coefficients (rest vertices and joints both are), so the coefficients
solve a small bounded least-squares problem on the tracker's point pairs pooled over the calibration
frames.  This is ours: the dissertation adapts limb lengths (ch. 5 §4.6, ch. 6 Algorithm 4) and the
surface only; a statistical shape basis first moves every part, the unseen ones too, the plausible way.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear

from ..geometry.rotations import matrix_to_quat
from ..rig.kinematics import forward_kinematics, world_rotations
from ..rig.model import Poses
from ..tracking.blend_body import linear_blend_weights
from .body_size import PartFrames, pooled

RIDGE = 0.01     # pull of every coefficient to 0 (the default body), relative to the data term's diagonal


class ShapeTerms:
    """Posed subset points of ``template.shaped(c)`` as ``c0 + sum_k c_k E_k`` (see the module docstring)."""

    def __init__(self, template):
        self.template = template
        base = template.base
        self.weights = linear_blend_weights(base)
        self.frames = PartFrames.of(base.skeleton)

    def __call__(self, ids, pose):
        base, pf = self.template.base, self.frames
        sk = base.skeleton
        Rm, tm = forward_kinematics(sk, pose)
        Rm, tm = Rm[0], tm[0]
        w = self.weights[ids]
        x = base.rest_vertices[ids]
        c0 = np.einsum("mb,brc,mc->mr", w, Rm, x) + w @ tm
        Jh = self.template.head_deltas                                  # (K, B, 3)
        K, B = Jh.shape[:2]
        chain = np.broadcast_to(Jh[:, :1], (K, B, 3)) - np.einsum("brc,kbc->kbr", Rm, Jh)
        rows, cols = np.nonzero(pf.path)
        via = pf.via[rows, cols]
        step = np.einsum("nrc,knc->knr", Rm[cols], Jh[:, via] - Jh[:, cols])
        acc = np.zeros((K, B, 3))
        np.add.at(acc, (slice(None), rows), step)
        chain = chain + acc
        blended = np.einsum("mb,brc->mrc", w, Rm)
        E = np.einsum("mb,kbr->mkr", w, chain) + np.einsum("mrc,kmc->mkr", blended, self.template.vertex_deltas[:, ids])
        return c0, E


def solve_coefficients(terms: ShapeTerms, frames) -> np.ndarray:
    """Basis coefficients in [0, 1] from the frames' pairs (ridge to the default body)."""
    K = terms.template.num_basis
    H, g = pooled(frames, terms, K)
    H = H + RIDGE * max(float(np.mean(np.diag(H))), 1e-9) * np.eye(K)
    L = np.linalg.cholesky(H)
    return lsq_linear(L.T, np.linalg.solve(L, g), bounds=(0.0, 1.0)).x


def same_world_pose(old_skeleton, new_skeleton, pose: Poses) -> Poses:
    """``pose`` re-expressed for a skeleton with other rest frames so every joint's world rotation is
    kept (``R(q') = F'ᵀ F R(q) Fᵀ F'``)."""
    R = world_rotations(old_skeleton, pose.rotations)
    F = new_skeleton.frames
    local = np.swapaxes(F, -1, -2)[None] @ R @ F[None]
    return Poses(matrix_to_quat(local), pose.translations.copy(), pose.scales.copy())
