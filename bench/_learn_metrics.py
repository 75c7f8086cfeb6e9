"""Evaluation metrics of learned rigs: reconstruction error, its statistics in millimetres, joint-centre
error against a reference rig, and Dem Bones' RMSE (``./run bench learn``; tests/bench/test_learn_metrics.py
checks them against brute-force references).  Benchmarks import it after ``_common``.

* :func:`scan_to_model_distances` — the reconstruction metric (dissertation (model-adaptive mocap) §4.1,
  §6.1): for every vertex of every target scan, the Euclidean distance to the closest point of the posed model's *surface*
  (triangles, not vertices), one direction (scan → model).  Exact, by
  :func:`solver.geometry.surface_distance.distance_to_surface`.
* :func:`statistics_mm` — mean, std, median, MAD, IQR, max of metre values, in mm
  (:func:`solver.geometry.surface_distance.error_statistics`: MAD = median |x − median|; Q1/Q3 = medians of the lower
  and upper halves, the middle element excluded for odd n).
* :func:`match_joints` — a learned skeleton has its own joint order and count; each learned joint centre
  is assigned to a distinct reference joint minimising the summed distance (Hungarian algorithm,
  ``scipy.optimize.linear_sum_assignment``).  Given joint *trajectories* ``(M, J, 3)`` (joints posed in every
  frame, e.g. :func:`posed_joints`), one assignment is made for all frames with the mean distance over the
  frames as cost — needed when the learned rest pose is one of the scans, not the reference's rest pose.
* :func:`dem_bones_rmse` — the RMSE Dem Bones prints and publishes: ``sqrt(Σ_frames Σ_vertices ‖x̂ − x‖² /
  (N·V))``, i.e. the root mean square of per-vertex Euclidean distances (not divided by 3 coordinates), in
  the units of the data.

Inputs in metres unless stated.
"""
from dataclasses import dataclass

import numpy as np

from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.surface_distance import error_statistics, per_vertex_scan_distances


def _points(name, x, ndim):
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != ndim or a.shape[-1] != 3:
        want = "(V, 3)" if ndim == 2 else "(N, V, 3)"
        raise ArticulaInputError(f"{name}: expected shape {want}, got {a.shape}")
    bad = np.argwhere(~np.isfinite(a))
    if len(bad):
        raise ArticulaInputError(f"{name}: non-finite value at index {tuple(int(i) for i in bad[0])}")
    return a


def scan_to_model_distances(scans, posed, faces):
    """``(N, V_scan)`` distances (m) of every scan vertex to the posed model surface of the same frame.

    scans ``(N, V_scan, 3)`` target vertices (registered or not); posed ``(N, V, 3)`` the model posed per
    frame; faces ``(F, 3)`` the model's triangles."""
    scans, posed = _points("scans", scans, 3), _points("posed", posed, 3)
    if len(scans) != len(posed):
        raise ArticulaInputError(f"posed: {len(posed)} frames for {len(scans)} scans")
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ArticulaInputError(f"faces: expected shape (F, 3) with F > 0, got {faces.shape}")
    if faces.min() < 0 or faces.max() >= posed.shape[1]:
        raise ArticulaInputError(f"faces: indices must lie in 0..{posed.shape[1] - 1}")
    return per_vertex_scan_distances(scans, posed, faces)


def statistics_mm(values_m) -> dict:
    """Statistics (``mean std median mad iqr max`` in mm, and ``count``) of distances given in metres."""
    stats = error_statistics(values_m)
    return {k: (v if k == "count" else 1000.0 * v) for k, v in stats.items()}


@dataclass
class JointMatch:
    """learned (K,), reference (K,): indices of the matched joints (K = min of the two counts);
    distances (K,): their distances in metres, in the order of ``learned``."""
    learned: np.ndarray
    reference: np.ndarray
    distances: np.ndarray


def match_joints(learned, reference) -> JointMatch:
    """Assign every learned joint centre ``(J1, 3)`` to a distinct reference joint ``(J2, 3)`` (or the other
    way round when J1 > J2) so that the summed distance is minimal.  With trajectories ``(M, J1, 3)`` and
    ``(M, J2, 3)`` the cost of a pair is its distance averaged over the M frames, and ``distances`` are
    those averages."""
    from scipy.optimize import linear_sum_assignment
    ndim = np.ndim(learned)
    if ndim not in (2, 3):
        raise ArticulaInputError(f"learned: expected shape (J, 3) or (M, J, 3), got {np.shape(learned)}")
    a, b = _points("learned", learned, ndim), _points("reference", reference, ndim)
    if ndim == 3 and len(a) != len(b):
        raise ArticulaInputError(f"reference: {len(b)} frames for {len(a)} learned frames")
    if not a.shape[-2] or not b.shape[-2]:
        raise ArticulaInputError(f"match_joints: need joints on both sides, got {a.shape[-2]} and {b.shape[-2]}")
    cost = np.linalg.norm(a[..., :, None, :] - b[..., None, :, :], axis=-1)
    if ndim == 3:
        cost = cost.mean(axis=0)
    i, j = linear_sum_assignment(cost)
    return JointMatch(i, j, cost[i, j])


def posed_joints(skeleton, poses):
    """Joint centres in every frame ``(N, B, 3)``: ``heads[b]`` moved by its part's chain map (a joint is
    the fixed point of its own rotation, so this is also where the parent part carries it)."""
    from articula.solver.rig.kinematics import forward_kinematics
    Rm, tm = forward_kinematics(skeleton, poses)
    return np.einsum("nbij,bj->nbi", Rm, skeleton.heads) + tm


def dem_bones_rmse(reconstructed, targets) -> float:
    """Dem Bones' RMSE (module docstring) of ``reconstructed`` against ``targets``, both ``(N, V, 3)``."""
    x, y = _points("reconstructed", reconstructed, 3), _points("targets", targets, 3)
    if x.shape != y.shape:
        raise ArticulaInputError(f"reconstructed: shape {x.shape} differs from targets {y.shape}")
    d = x - y
    return float(np.sqrt(np.einsum("nvi,nvi->", d, d) / (x.shape[0] * x.shape[1])))
