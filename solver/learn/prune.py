"""Leaf bones that hold no vertex, removed after learning.

The weight step can take every vertex from an end part (a small part cut at a blend zone, a segment the
weights explain better with its parent's motion): the bone is then left in the rig moving nothing, which
an animator sees as a stray control.  A leaf bone with no vertex anchored to it and no swing or twist
weight above WEIGHT_TOL moves no vertex and no other bone, so removing it changes no posed surface; its
parent may then become such a leaf in turn.  Bone order (parents before children) is kept.
"""
import numpy as np

from ..rig.model import Model, Poses, Skeleton

WEIGHT_TOL = 1e-3       # a weight below this moves a vertex by under a millimetre per metre of bone motion


def empty_leaves(model, tol=WEIGHT_TOL):
    """Bones (sorted) to drop from ``model``: leaves without anchored vertices or weights above ``tol``,
    repeatedly (a parent left as such a leaf goes too); never the root."""
    sk = model.skeleton
    used = np.bincount(model.anchor, minlength=sk.num_bones) > 0
    used |= np.maximum(model.swing_weights.max(axis=0), model.twist_weights.max(axis=0)) > tol
    alive = np.ones(sk.num_bones, dtype=bool)
    changed = True
    while changed:
        children = np.bincount(sk.parents[1:][alive[1:]], minlength=sk.num_bones)
        drop = alive & ~used & (children == 0)
        drop[0] = False
        changed = bool(drop.any())
        alive &= ~drop
    return np.flatnonzero(~alive)


def drop_bones(model, poses, drop):
    """``(model, poses, new_index (B,))`` without the bones ``drop`` (leaves that move nothing, as
    :func:`empty_leaves` finds); ``new_index[b]`` is b's index afterwards, -1 if dropped."""
    B = model.skeleton.num_bones
    keep = np.setdiff1d(np.arange(B), drop)
    new_index = np.full(B, -1, dtype=np.int64)
    new_index[keep] = np.arange(len(keep))
    sk = model.skeleton
    parents = np.where(sk.parents[keep] >= 0, new_index[np.maximum(sk.parents[keep], 0)], -1)
    skeleton = Skeleton([sk.names[b] for b in keep], parents, sk.heads[keep], sk.tails[keep], sk.frames[keep])
    out = Model(model.rest_vertices, model.faces, skeleton, new_index[model.anchor],
                model.twist_weights[:, keep], model.swing_weights[:, keep])
    return out, Poses(poses.rotations[:, keep], poses.translations, poses.scales), new_index


def remap_pairs(pairs, new_index):
    """Tuples of bone indices (mirror pairs, symmetry terms) renumbered; a tuple naming a dropped bone goes."""
    out = []
    for pair in pairs:
        mapped = tuple(int(new_index[b]) for b in pair)
        if min(mapped) >= 0:
            out.append(mapped)
    return out
