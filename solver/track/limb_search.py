"""Limbs placed on the first frame by searching each bone's direction, for models whose bones have no
known names (a rig learned by ``learn_rig``) or whose training poses are unlike the capture's.

The per-frame fit (:mod:`.frame_fit`) is a local method: from a hypothesis with the trunk placed but an
arm raised where the capture's hangs, the ICP pulls the arm onto the nearest surface (often the trunk)
and stays there (docs/track.md "First frame").  Here, bone by bone from the root outwards, the bone and
everything below it turn rigidly about the bone's posed joint centre to each of ``DIRECTIONS`` directions
spread over the sphere (the direction of a bone: from its joint to the centroid of the vertices it and its
descendants carry), and the direction whose vertices lie closest to the capture points not yet explained
by the bones placed before it wins (mean distance truncated at ``TRUNCATE_M``; a capture point is explained
when a placed vertex is within ``EXPLAINED_M``, so a limb is not laid onto the trunk's surface).  A bone
keeps its pose unless the best direction lowers that score by ``MIN_GAIN``.  No names, no training poses:
it works for any skeleton.  The twist about the bone is left as it was; the full fit refines it all.
This step is not in the dissertation, which starts from a manual placement (§4.1.2).
"""
import numpy as np
from scipy.spatial import cKDTree

from ..geometry.rotations import matrix_to_quat, rotation_between
from ..rig.kinematics import forward_kinematics
from ..rig.model import Poses
from ..rig.skinning import hybrid_skin
from ..tracking.limbs import bone_depths, sphere_directions, subtrees

DIRECTIONS = 64          # directions tried per bone (Fibonacci sphere, about 25 deg apart)
TRUNCATE_M = 0.05        # a vertex farther than this from the capture counts as this far
EXPLAINED_M = 0.02       # a capture point this close to a placed vertex is explained
MIN_GAIN = 0.8           # a new direction must bring the score below this fraction of the old one
SAMPLE = 400             # vertices scoring a candidate (spread over the bone's subtree)
PASSES = 1               # sweeps over the bones (more measured no better, docs/track.md)
MIN_VERTICES = 20        # bones carrying fewer vertices (with their descendants) are not searched


def search_order(parents) -> list:
    """Bones 1..B-1 by depth in the tree, then index: every bone of one depth (the trunk's next piece and
    the limbs' first bones) is placed before any deeper one claims their capture points."""
    depth = bone_depths(parents)
    return sorted(range(1, len(parents)), key=lambda b: (depth[b], b))


def _score(tree, vertices):
    if tree is None:
        return TRUNCATE_M
    d = tree.query(vertices, distance_upper_bound=TRUNCATE_M)[0]
    return float(np.minimum(d, TRUNCATE_M).mean())


def place_limbs(model, pose: Poses, points, groups=None, directions: int = DIRECTIONS,
                passes: int = PASSES) -> Poses:
    """``pose`` (one frame) with every bone's direction chosen on the capture ``points (N, 3)`` (metres),
    root first, ``passes`` times (module docstring).  The root's pose is kept.  Returns a new
    :class:`Poses`."""
    pose = Poses(pose.rotations.copy(), pose.translations.copy(), pose.scales.copy())
    for _ in range(passes):
        pose = _one_pass(model, pose, points, groups, sphere_directions(directions))
    return pose


def _one_pass(model, pose, points, groups, cand):
    sk = model.skeleton
    owner = subtrees(sk.parents)
    anchor = np.asarray(model.anchor)
    rng = np.random.default_rng(0)
    placed = anchor == 0
    posed = hybrid_skin(model, pose, groups)[0]
    for b in search_order(sk.parents):
        carried = np.flatnonzero(np.isin(anchor, owner[b]))
        if len(carried) < MIN_VERTICES:
            placed |= anchor == b
            continue
        free = np.ones(len(points), dtype=bool)
        if placed.any():
            free = cKDTree(posed[placed]).query(points, distance_upper_bound=EXPLAINED_M)[0] > EXPLAINED_M
        tree = cKDTree(points[free]) if free.any() else None
        sample = posed[rng.choice(carried, min(SAMPLE, len(carried)), replace=False)]
        Rm, tm = forward_kinematics(sk, pose)
        joint = Rm[0, b] @ sk.heads[b] + tm[0, b]
        d = sample.mean(axis=0) - joint
        if np.linalg.norm(d) < 1e-6:
            placed |= anchor == b
            continue
        G = rotation_between(d / np.linalg.norm(d), cand)
        moved = np.einsum("kij,nj->kni", G, sample - joint) + joint
        scores = np.array([_score(tree, m) for m in moved])
        best = int(np.argmin(scores))
        if scores[best] < MIN_GAIN * _score(tree, sample):
            pose = _turned(sk, pose, b, G[best], Rm[0])
            posed = hybrid_skin(model, pose, groups)[0]
        placed |= anchor == b
    return pose


def _turned(sk, pose, b, G, Rm):
    """``pose`` with bone b's world rotation preceded by the world turn ``G`` about its joint:
    joint rotation ``R_b' = (Rm_p)⁻¹ G Rm_b`` (scale cancels), local ``F_bᵀ R_b' F_b``."""
    p = sk.parents[b]
    Rp, Rb = Rm[p], Rm[b]
    R_joint = np.linalg.solve(Rp, G @ Rb)
    F = sk.frames[b]
    out = Poses(pose.rotations.copy(), pose.translations, pose.scales)
    out.rotations[0, b] = matrix_to_quat(F.T @ R_joint @ F)
    return out
