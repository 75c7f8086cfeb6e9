"""Body poses the depth tracker starts from: the rest pose, the shipped generic body poses (walk frames:
arms down, legs apart) mapped onto any rig by bone role, and a model's training poses, spread."""
from __future__ import annotations

import os

import numpy as np

from ..geometry.rotations import matrix_to_quat, quat_to_matrix
from ..rig.model import Poses
from ..roles import bone_keys

GENERIC_POSES_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "generic_body_poses.npz")


def body_poses(skeleton, training_poses: Poses = None, count: int = 24, generic: bool = True) -> Poses:
    """Up to ``count`` body poses: the rest pose, the generic body poses (:func:`generic_body_poses`, walk
    frames: arms down, legs apart, which range-of-motion training poses rarely are) and the training
    poses, each set spread evenly (every k-th) over at most half of the rest; root rotation, translation
    and scale reset (the facing and position are searched)."""
    sets = [Poses.identity(1, skeleton.num_bones).rotations]
    extra = generic_body_poses(skeleton) if generic else None
    for source in (extra, training_poses):
        if source is not None and len(source) and count > 1:
            pick = np.unique(np.linspace(0, len(source) - 1, min(len(source), max(1, (count - 1) // 2)))
                             .round().astype(int))
            sets.append(source.rotations[pick])
    rot = np.concatenate(sets)
    rot[:, 0] = (1.0, 0.0, 0.0, 0.0)
    return Poses(rot, np.zeros((len(rot), 3)), np.ones(len(rot)))


def generic_body_poses(skeleton, path: str = GENERIC_POSES_PATH) -> Poses:
    """The shipped generic body poses (walk frames of the cmu_mb rig, ``tools/make_generic_poses.py``)
    mapped onto ``skeleton`` by bone role (:func:`solver.roles.bone_keys`), each local rotation re-expressed
    in the model's rest frame (``F'ᵀ F R Fᵀ F'``); bones that do not map stay at rest.  None when no bone
    other than the root maps."""
    with np.load(path, allow_pickle=False) as data:
        names, frames, rotations = list(data["names"]), data["frames"], data["rotations"]
    index = {k: i for i, k in enumerate(bone_keys([str(n) for n in names]))}
    out = Poses.identity(len(rotations), skeleton.num_bones)
    mapped = 0
    for b, key in enumerate(bone_keys(skeleton.names)[1:], start=1):
        s = index.get(key)
        if s is None or s == 0:
            continue
        C = skeleton.frames[b].T @ frames[s]
        R = C @ quat_to_matrix(rotations[:, s]) @ C.T
        out.rotations[:, b] = matrix_to_quat(R)
        mapped += 1
    return out if mapped else None
