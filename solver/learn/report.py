"""The report of a rig-learning run: how well the learned model reproduces the scans.

The error measure is the reconstruction metric of dissertation (model-adaptive mocap) §6.1: the exact
distance of every scan vertex to the posed model's surface (point to triangle), summarised in mm.
"""
import numpy as np

from ..geometry.surface_distance import error_statistics, per_vertex_scan_distances
from ..rig.skinning import hybrid_skin
from .joints_poses import symmetry_residuals

STAGE = "report: distances of every scan to the learned surface"


def make_report(model, poses, scans, objective, sym, progress=None):
    """``(report, distances (M,V))`` for ``model`` posed by ``poses`` against ``scans (M,V,3)`` metres:
    error statistics in mm of every scan vertex to the posed model surface (``surface_error_mm``: mean,
    std, median, MAD, IQR, max, count), the vertex-to-vertex RMS (``vertex_rms_mm``), Q of ``objective``
    (``objective_Q``, m²) and, for the mirror pairs ``sym`` (:func:`solver.learn.joints_poses.symmetry_residuals`),
    their bone-length differences in mm; ``distances`` are the point-to-surface distances in metres.
    progress(fraction, stage, None): after each batch of frames of the distances; may raise ``Cancelled``."""
    say = (lambda f: None) if progress is None else (lambda f: progress(f, STAGE, None))
    posed = hybrid_skin(model, poses)
    say(0.05)
    d = per_vertex_scan_distances(scans, posed, model.faces, progress=lambda f: say(0.05 + 0.9 * f))
    stats = {k: (v if k == "count" else v * 1e3) for k, v in error_statistics(d).items()}
    report = dict(surface_error_mm=stats,
                  vertex_rms_mm=float(np.sqrt(np.mean(np.sum((posed - scans) ** 2, axis=2))) * 1e3),
                  objective_Q=objective.value(posed))
    if sym:
        r, _ = symmetry_residuals(model.skeleton, sym)
        report["symmetry_length_difference_mm"] = (np.abs(r) * 1e3).tolist()
    return report, d
