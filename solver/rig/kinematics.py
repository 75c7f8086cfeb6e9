"""Forward kinematics of the part chain (dissertation (model-adaptive mocap) §1.2; docs/skinning.md).

Every joint rotates about its *rest* centre ``heads[b]``; rotations are converted from bone-local
axes to world axes with the rest frame: ``R_b = F_b R(q_b) F_bᵀ``.  The chain of part b is
``M_b = M_parent(b) ∘ Rot(R_b about heads[b])`` and the root is the similarity
``M_0(x) = s R_0 (x − heads[0]) + heads[0] + t``.  ``M_b(x) = Rm[b] x + tm[b]``.
"""
import functools

import numpy as np

from ..geometry.rotations import quat_to_matrix


def to_world(frames, R_local):
    """``F R Fᵀ``: local-axes rotations ``(..., B, 3, 3)`` to world axes with frames ``(B, 3, 3)``."""
    return frames @ R_local @ np.swapaxes(frames, -1, -2)


def world_rotations(skeleton, rotations):
    """World-axes joint rotations ``(N, B, 3, 3)`` from quaternions ``(N, B, 4)`` in bone-local axes."""
    return to_world(skeleton.frames, quat_to_matrix(rotations))


@functools.lru_cache(maxsize=64)
def _levels(parents: tuple) -> tuple:
    """The non-root bones grouped by depth in the tree, ``((bones, their parents), ...)`` top down: each
    group's chain maps follow from the previous group's at once."""
    depth = [0] * len(parents)
    for b in range(1, len(parents)):
        depth[b] = depth[parents[b]] + 1
    out = []
    for d in range(1, max(depth, default=0) + 1):
        bones = np.array([b for b in range(len(parents)) if depth[b] == d], dtype=np.int64)
        out.append((bones, np.asarray(parents, dtype=np.int64)[bones]))
    return tuple(out)


def chain_from_world(skeleton, R, translations, scales):
    """Chain maps from world-axes joint rotations.

    R ``(N, B, 3, 3)``, translations ``(N, 3)``, scales ``(N,)``.  Returns ``Rm (N, B, 3, 3)`` and
    ``tm (N, B, 3)`` with part b mapping x -> Rm[:, b] x + tm[:, b] (Rm includes the scale).  Bones of one
    depth in the tree are composed together (parents come first, ``parents[b] < b``)."""
    h = skeleton.heads
    N, B = R.shape[:2]
    Rm = np.empty((N, B, 3, 3))
    tm = np.empty((N, B, 3))
    s = np.asarray(scales, dtype=np.float64)[:, None, None]
    Rm[:, 0] = s * R[:, 0]
    tm[:, 0] = h[0] - Rm[:, 0] @ h[0] + np.asarray(translations, dtype=np.float64)
    # M_p(R_b (x - h_b) + h_b) = Rm_p R_b x + Rm_p (h_b - R_b h_b) + tm_p
    offset = h - np.einsum("nbij,bj->nbi", R, h)                       # (N, B, 3)
    for bones, parents in _levels(tuple(int(p) for p in skeleton.parents)):
        Rp = Rm[:, parents]
        Rm[:, bones] = Rp @ R[:, bones]
        tm[:, bones] = np.einsum("nbij,nbj->nbi", Rp, offset[:, bones]) + tm[:, parents]
    return Rm, tm


def forward_kinematics(skeleton, poses):
    """Rigid chain maps of every part: ``(Rm (N, B, 3, 3), tm (N, B, 3))``, x -> Rm x + tm,
    root scale and translation included."""
    R = world_rotations(skeleton, poses.rotations)
    return chain_from_world(skeleton, R, poses.translations, poses.scales)
