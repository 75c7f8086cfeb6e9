"""Limbs placed by searching each bone's direction on the first frame (and after the person was lost),
for arms and legs the start hypotheses hold elsewhere (ours; the scan tracker's limb search,
:mod:`solver.track.limb_search`, adapted to one depth camera): bone by bone from the root outwards the
bone's subtree turns rigidly about its posed joint to each of ``DIRECTIONS`` directions, and the
direction with the lowest whole-body score (:func:`body_score`: observed points the model does not
explain plus model points in free space) wins when it beats the current pose by ``MIN_GAIN``.  The
whole-body score keeps a limb from being laid over data another part explains."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.rotations import matrix_to_quat, quat_to_rotvec, rotation_between
from ..track.frame_fit import bone_depths
from ..track.limb_search import sphere_directions, subtrees

DIRECTIONS = 64
MIN_GAIN = 0.01          # absolute score decrease a new direction must bring
MIN_POINTS = 8           # bones whose subtree holds fewer subset points are not searched
SCORE_POINTS = 600       # observed points scoring a candidate


def body_score(points, obs, camera, near_m: float, sample) -> float:
    """Share of the sampled observed points farther than ``near_m`` from every model point, plus the
    share of model points in free space (lower is better)."""
    d, _ = cKDTree(points).query(sample, distance_upper_bound=near_m)
    return float(np.isinf(d).mean() + obs.in_free_space(points, camera).mean())


def place_limbs(body, pose, obs, camera, near_m: float):
    """``pose`` (one frame) with bone directions chosen on the observation (module docstring)."""
    sk = body.model.skeleton
    owner = subtrees(sk.parents)
    depth = bone_depths(sk.parents)
    cand = sphere_directions(DIRECTIONS)
    sample = obs.points[:: max(1, len(obs.points) // SCORE_POINTS)]
    posed = body.pose(pose)
    current = body_score(posed.points, obs, camera, near_m, sample)
    for b in sorted(range(1, sk.num_bones), key=lambda c: (depth[c], c)):
        rows = np.flatnonzero(np.isin(body.main_bone, owner[b]))
        joint = posed.joints[b]
        d = posed.points[rows].mean(axis=0) - joint if len(rows) else np.zeros(3)
        if len(rows) < MIN_POINTS or np.linalg.norm(d) < 1e-6:
            continue
        G = rotation_between(d / np.linalg.norm(d), cand)                        # (K, 3, 3)
        pts = posed.points.copy()
        scores = []
        for g in G:
            pts[rows] = (posed.points[rows] - joint) @ g.T + joint
            scores.append(body_score(pts, obs, camera, near_m, sample))
        best = int(np.argmin(scores))
        if scores[best] < current - MIN_GAIN:
            delta = np.zeros(body.num_params)
            delta[3 + 3 * b:6 + 3 * b] = quat_to_rotvec(matrix_to_quat(G[best]))
            pose = body.apply(pose, delta, posed)
            posed = body.pose(pose)
            current = body_score(posed.points, obs, camera, near_m, sample)
    return pose
