"""The tracker's report on each frame: capture-to-model distances and the truth-free checks.

Distances: every capture point to the closest point of the posed model's triangles, exact
(:func:`.metrics.point_to_mesh`), summarised by mean, median, MAD and IQR (dissertation §4.2, Eq.
4.17-4.18).  Checks (:func:`solver.tracking.checks.check_frame`): capture regions the model leaves
unexplained, model parts the cameras saw through, limbs lying on or in other parts, joints past their
limits; a frame that fails them is "doubtful" or "lost" whatever its residual.
"""
from __future__ import annotations

from ..parallel import map_pieces, workers
from ..tracking.checks import check_frame
from . import metrics
from .adaptation import SHAPE_OFF
from .options import ADAPT_MIN_FRAMES


def assess(body, rec, poses, checked=None) -> list:
    """Fill every usable frame's entry with its distances and, when ``options.checks``, its verdict and
    reasons (``checked``: the model prepared by :func:`solver.tracking.checks.prepare`, None: no checks).
    Returns the input frames the checks flag (doubtful or lost): their poses are kept (a check
    can be wrong where the subject really touches itself) and the report says so.  Frames are assessed
    on the solver's threads a few at a time (captures are read in this thread: the recording's cache is
    not shared)."""
    doubtful, usable = [], rec.usable()
    batch = 2 * workers()
    for first in range(0, len(usable), batch):
        chunk = [(i, poses.take(i), rec.capture(i)) for i in usable[first:first + batch]]
        for (i, _, _), (stats, verdict) in zip(chunk, map_pieces(lambda item: _assessed(body, checked, *item[1:]),
                                                                 chunk)):
            entry = rec.entries[i]
            entry.update(mean_mm=stats["mean"], median_mm=stats["median"], mad_mm=stats["mad"], iqr_mm=stats["iqr"])
            if verdict is None:
                continue
            entry.update(verdict=verdict.verdict, checks=list(verdict.reasons))
            if verdict.verdict != "good":
                doubtful.append(rec.range[i])
    return doubtful


def _assessed(body, checked, pose, capture):
    """``(distance statistics (mm), verdict or None)`` of one frame."""
    posed = body.pose(pose)
    stats = metrics.robust_stats(metrics.point_to_mesh(capture.points, posed, body.model.faces) * 1e3)
    return stats, None if checked is None else check_frame(body.model, pose, posed, capture, checked)


def adapt_note(rec, offset, adapted) -> list:
    """What "auto" adaptation decided when the model lies off the captures (``offset``, m; None: not
    "auto"): adapted, or too few frames to adapt on."""
    if offset is None or offset <= SHAPE_OFF:
        return []
    off = f"adaptation: the model lies {offset * 1e3:.1f} mm off the captures (more than {SHAPE_OFF * 1e3:g} mm)"
    if adapted:
        return [f"{off}; its rest shape and joints were adapted to them"]
    return [f"{off}, but {len(rec)} frame(s) are too few to adapt on (at least {ADAPT_MIN_FRAMES}); adapt "
            f"\"on\" adapts anyway"]


def notes(rec, prior_name, options, doubtful) -> list:
    """Summary notes: which prior ran, poor fits, frames lost or doubtful by the checks."""
    out = []
    if prior_name == "generic":
        out.append("pose prior: the generic human prior (the model has fewer than 3 poses of its own)"
                   if options.prior == "auto" else "pose prior: the generic human prior")
    entries = [e for e in rec.entries if e is not None]
    poor = [e["frame"] for e in entries
            if not e["skipped"] and e["median_mm"] is not None and e["median_mm"] > options.poor_fit_mm]
    if poor:
        out.append(f"poor fit: {len(poor)} frame(s) have a median scan-to-model distance above "
                   f"{options.poor_fit_mm:g} mm (first: frame {poor[0]}); is it the same person and the right model?")
    lost = [e for e in entries if e["lost"]]
    if lost:
        out.append(f"lost: {len(lost)} frame(s) (first: frame {lost[0]['frame']}: {lost[0]['reason']}); their poses "
                   f"are interpolated")
    if doubtful:
        first = next(e for e in entries if e["frame"] == doubtful[0])
        called = sum(e["verdict"] == "lost" for e in entries)
        out.append(f"checks: {len(doubtful)} frame(s) fail a check, {called} of them badly (the fit is likely "
                   f"wrong there; first: frame {doubtful[0]}: {first['checks'][0] if first['checks'] else ''})")
    return out
