"""The tracking report on the Blender side: the solver's report (``TrackResult.report()``: per-frame
residual statistics in mm, lost and skipped frames, time per stage) with the run's model, input and
options as JSON (stored on the armature as ``articula_track_report`` and in a saved bundle's provenance),
and its one-line summary."""
import dataclasses

import numpy as np

from ..learn.report import jsonable
from ..tracking.result import residuals_mm

def options_dict(options) -> dict:
    """The tracking options as JSON types, without the frame range (what chunks of one run share)."""
    d = jsonable(dataclasses.asdict(options))
    d.pop("frames", None)
    return d


def report_document(outcome) -> dict:
    """The report JSON of a :class:`addon.track.solve.TrackOutcome`: the solver's report plus ``model``
    (label, digest, vertices, bones, training poses), ``input`` (label, frames, tracked range, how the
    first frame started: "automatic", "the rig's pose", "pose K of FILE"), ``options``
    and, when measured, ``point_error_mm`` (median, mean, 95th percentile over every capture point of the
    tracked frames)."""
    result, mi, cap = outcome.result, outcome.model_input, outcome.captures
    doc = jsonable(result.report())
    doc["model"] = {"source": mi.label, "sha256": mi.sha256, "vertices": int(mi.model.num_vertices),
                    "bones": int(mi.model.skeleton.num_bones),
                    "training_poses": 0 if mi.training_poses is None else int(len(mi.training_poses))}
    doc["input"] = {"source": cap.label, "frames": len(cap.names), "first_frame": outcome.first_frame,
                    "tracked": int(len(result.poses)),
                    "start": (mi.start_label or "given") if mi.start_pose is not None else "automatic"}
    doc["options"] = options_dict(outcome.options)
    if outcome.point_errors_mm:
        e = np.concatenate(outcome.point_errors_mm)
        e = e[np.isfinite(e)]
        if len(e):
            doc["point_error_mm"] = {"median": float(np.median(e)), "mean": float(np.mean(e)),
                                     "p95": float(np.percentile(e, 95))}
    return doc


def summary_text(outcome) -> str:
    """One line: frames tracked (input frame indices), their median residual, lost/skipped frames and the
    frames failing the truth-free fit checks (input frame indices), the prior and adaptation; the solver's
    notes are reported separately."""
    result = outcome.result
    n = len(result.poses)
    med = residuals_mm(result)
    parts = [f"{n} frame{'s' if n != 1 else ''} tracked (input frames {outcome.first_frame}.."
             f"{outcome.first_frame + n - 1})"]
    if np.isfinite(med).any():
        parts.append(f"median residual {np.nanmedian(med):.2f} mm (worst frame {np.nanmax(med):.2f} mm)")
    if result.lost:
        parts.append(f"{len(result.lost)} lost (not recovered by re-initialisation, poses interpolated): "
                     f"{_frames(result.lost)}")
    if result.skipped:
        parts.append(f"{len(result.skipped)} skipped (poses interpolated): {_frames(result.skipped)}")
    flagged = list(getattr(result, "doubtful", ()))
    if flagged:
        parts.append(f"{len(flagged)} failing the fit checks (likely wrong, see the report): {_frames(flagged)}")
    elif getattr(result, "frames", None) and any(f.get("verdict") for f in result.frames):
        parts.append("every frame passes the fit checks")
    parts.append(f"pose prior: {result.prior}")
    parts.append("model adapted" if result.adapted else "model not adapted")
    return "; ".join(parts)


def _frames(indices, at_most: int = 8) -> str:
    shown = ", ".join(str(int(i)) for i in list(indices)[:at_most])
    return shown + (", …" if len(indices) > at_most else "")
