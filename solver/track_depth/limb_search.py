"""Limbs placed by searching each bone's direction on the first frame (and after the person was lost),
for arms and legs the start hypotheses hold elsewhere (ours; the scan tracker's former limb search,
adapted to one depth camera): bone by bone from the root outwards the
bone's subtree turns rigidly about its posed joint to each of ``DIRECTIONS`` directions and, for limbs
(subtrees of ``LIMB_POINTS`` points), the child's subtree too for each of the bone's ``PAIRED`` best
directions (a bent elbow is found with the upper arm); the configuration with the lowest whole-body
score (observed points the model does not explain plus model points in free space) wins when it beats
the current pose by ``MIN_GAIN``.  The whole-body score keeps a limb from being laid over data another
part explains."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.rotations import matrix_to_quat, quat_to_rotvec, rotation_between
from ..tracking.limbs import bone_depths, sphere_directions, subtrees
from .orientation import view_frame

DIRECTIONS = 128
PAIRED = 6               # a limb's best directions for which its child's direction is searched too
LIMB_POINTS = (40, 400)  # subtree sizes (subset points) searched with their child
MIN_GAIN = 0.01          # absolute score decrease a new configuration must bring
MIN_POINTS = 8           # bones whose subtree holds fewer subset points are not searched
SCORE_POINTS = 600       # observed points scoring a candidate


class _Scorer:
    """Whole-body score with one subtree (``rows``) moving: the rest of the model is fixed, so its
    distances to the observed sample and its free-space count are computed once."""

    def __init__(self, points, rows, obs, camera, near_m, sample):
        self.obs, self.camera, self.near, self.sample = obs, camera, near_m, sample
        fixed = np.ones(len(points), bool)
        fixed[rows] = False
        self.M = len(points)
        d = cKDTree(points[fixed]).query(sample, distance_upper_bound=near_m)[0] if fixed.any() else np.full(len(sample), np.inf)
        self.unexplained = ~np.isfinite(d)
        self.free_fixed = int(obs.in_free_space(points[fixed], camera).sum())

    def __call__(self, moving) -> float:
        d = cKDTree(moving).query(self.sample[self.unexplained], distance_upper_bound=self.near)[0]
        miss = int((~np.isfinite(d)).sum())
        free = self.free_fixed + int(self.obs.in_free_space(moving, self.camera).sum())
        return miss / len(self.sample) + free / self.M


def _turns(points, joint, cand):
    d = points.mean(axis=0) - joint
    if np.linalg.norm(d) < 1e-6:
        return None
    return rotation_between(d / np.linalg.norm(d), cand)                         # (K, 3, 3)


def _apply(body, pose, b, G):
    """``pose`` with bone b's subtree turned by the world rotation ``G`` (3, 3) about its joint."""
    delta = np.zeros(body.size)
    A = body.axes(body.pose(pose))[b]
    delta[3 + 3 * b:6 + 3 * b] = A.T @ quat_to_rotvec(matrix_to_quat(G))
    return body.moved(pose, delta)


def _child(owner, rows_of, b, sk):
    kids = [c for c in range(b + 1, sk.num_bones) if sk.parents[c] == b]
    if not kids:
        return None
    c = max(kids, key=lambda k: len(rows_of(k)))
    return c if len(rows_of(c)) >= MIN_POINTS else None


def _search_bone(body, pose, b, child, rows_of, obs, camera, near_m, sample, cand):
    """The best ``(score, G_b, G_child or None)`` for bone b (and its child) and the current score."""
    posed = body.pose(pose)
    rows = rows_of(b)
    joint = posed.joints[b]
    scorer = _Scorer(posed.points, rows, obs, camera, near_m, sample)
    current = scorer(posed.points[rows])
    G = _turns(posed.points[rows], joint, cand)
    if G is None:
        return current, None, None, current
    moved = np.einsum("kij,nj->kni", G, posed.points[rows] - joint) + joint
    scores = np.array([scorer(m) for m in moved])
    best = (scores.min(), G[int(np.argmin(scores))], None)
    if child is None:
        return best + (current,)
    kid = np.flatnonzero(np.isin(rows, rows_of(child)))
    for k in np.argsort(scores)[:PAIRED]:
        m = moved[k].copy()
        cj = G[k] @ (posed.joints[child] - joint) + joint
        H = _turns(m[kid], cj, cand)
        if H is None:
            continue
        for h in H:
            m[kid] = (moved[k][kid] - cj) @ h.T + cj
            s = scorer(m)
            if s < best[0]:
                best = (s, G[k], h)
    return best + (current,)


def place_limbs(body, pose, obs, camera, near_m: float, up, held=()):
    """``pose`` (one frame) with bone directions chosen on the observation (module docstring); the
    directions are spread in the frame of ``up`` and the camera (:func:`.orientation.view_frame`).  The
    ``held`` bones (parts out of view, :mod:`.out_of_view`) are not searched."""
    sk = body.model.skeleton
    owner = subtrees(sk.parents)
    depth = bone_depths(sk.parents)
    cand = sphere_directions(DIRECTIONS) @ view_frame(camera.R, up).T
    sample = obs.points[:: max(1, len(obs.points) // SCORE_POINTS)]

    def rows_of(b):
        return np.flatnonzero(np.isin(body.main_bone, owner[b]))
    for b in sorted(range(1, sk.num_bones), key=lambda c: (depth[c], c)):
        n = len(rows_of(b))
        if n < MIN_POINTS or b in held:
            continue
        child = _child(owner, rows_of, b, sk) if LIMB_POINTS[0] <= n <= LIMB_POINTS[1] else None
        score, G, H, current = _search_bone(body, pose, b, child, rows_of, obs, camera, near_m, sample, cand)
        if G is not None and score < current - MIN_GAIN:
            pose = _apply(body, pose, b, G)
            if H is not None:
                pose = _apply(body, pose, child, H)
    return pose
