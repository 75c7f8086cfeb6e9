"""Key scans: a representative subset of a long registered sequence to learn the shared rig from.

The parameters that all scans share (skeleton, swing/twist weights, rest vertices) are fixed by far fewer
scans than an animation holds: consecutive frames of a 400-frame clip differ by a few degrees, so most of
them repeat what their neighbours say about the rig while multiplying the cost of every step of the
alternation.  This goes beyond dissertation (model-adaptive mocap) chapter 3, which learns from all scans
(it has ≤ 100 scans in mind): :func:`solver.learn.pipeline.learn_rig` learns from
``select_key_scans(scans, K)`` (K = ``LearnOptions.key_scans``) and then fits the pose of every other scan
with the learned model fixed (:func:`solver.fit.pose_fit.fit_poses`, the held-out fit).

Selection: farthest-point sampling over the scans' shapes with their rigid motion taken out.  Each scan is
rigidly aligned to the first key (Procrustes over a vertex subsample) and the scans are compared by the RMS
distance of the aligned subsample; starting from the first key, the scan farthest from all keys chosen so far
is added until there are K.  This picks the extreme poses first (the ones that pin joints and weights) and
never two near-identical frames.  Deterministic; units are those of the input (metres).

On large meshes the count is also held to a time budget, ``LearnOptions.key_scan_budget`` vertex-scans
(:func:`time_budget_count`).  docs/learn_rig_solver.md has the accuracy and time measured with and
without key scans.
"""
import numpy as np

from ..geometry.procrustes import fit_rigid

SUBSAMPLE = 1000      # vertices compared per scan (evenly spaced indices)
TIME_KEY_SCANS = 20   # the time budget never cuts the key scans below this many


def aligned_features(scans, first=0, subsample=SUBSAMPLE):
    """``(M, 3P)`` the scans' subsampled vertices (P ≤ ``subsample``) after the rigid fit of each scan to
    scan ``first``; scans ``(M, V, 3)``."""
    scans = np.asarray(scans, dtype=np.float64)
    V = scans.shape[1]
    idx = np.unique(np.linspace(0, V - 1, min(V, subsample)).round().astype(np.int64))
    x = scans[:, idx]
    R, t = fit_rigid(x, x[first][None])
    aligned = np.einsum("mij,mpj->mpi", R, x) + t[:, None]
    return aligned.reshape(len(scans), -1)


def select_key_scans(scans, count, first=0):
    """Indices (sorted, int64) of ``count`` key scans of ``scans (M, V, 3)`` including ``first``, by
    farthest-point sampling of the rigidly aligned shapes (module docstring).  All scans when
    ``count >= M``."""
    M = len(scans)
    if count >= M:
        return np.arange(M)
    if count < 1:
        raise ValueError(f"select_key_scans: count must be >= 1, got {count}")
    f = aligned_features(scans, first)
    keys = [int(first)]
    d = np.linalg.norm(f - f[first], axis=1)
    d[first] = -np.inf                      # chosen scans are never chosen again (even among duplicates)
    for _ in range(count - 1):
        j = int(np.argmax(d))
        keys.append(j)
        d = np.minimum(d, np.linalg.norm(f - f[j], axis=1))
        d[j] = -np.inf
    return np.sort(np.asarray(keys, dtype=np.int64))


def time_budget_count(num_vertices, requested, budget):
    """The key-scan count of a run on a mesh of ``num_vertices`` that asks for at most ``requested``: at
    most ``budget`` vertex-scans, but never below TIME_KEY_SCANS nor above ``requested``.  ``requested``
    0 (every scan, asked for) and ``budget`` 0 (no limit) leave ``requested`` as it is.  Every step of the
    alternation costs about key scans x vertices, so this holds the learning time of a large mesh near
    that of a 7,500-vertex one learned from 40 scans."""
    if budget <= 0 or requested <= 0:
        return requested
    return min(requested, max(TIME_KEY_SCANS, int(budget // max(num_vertices, 1))))
