"""The depth-tracking report on the Blender side: the solver's report (``DepthTrackResult.report()``: per
frame its status, correspondences and mean distance, time per frame) with the run's model, input and
coordinates as JSON (stored on the armature as ``articula_track_report`` and in a saved bundle's
provenance), and its one-line summary."""
import dataclasses

import numpy as np

from ...solver.tracking.provenance import model_digest
from ..learn.report import jsonable

STATUSES = ("tracked", "initialised", "lost", "no person")


def options_dict(options) -> dict:
    """The depth-tracking options as JSON types."""
    return jsonable(dataclasses.asdict(options))


def report_document(outcome) -> dict:
    """The report JSON of a :class:`addon.track_depth.solve.DepthOutcome`: the solver's report plus
    ``model`` (source, digests of the given and the tracked model, vertices, bones, template) and ``input``
    (source, frames, first tracked frame, tracked frames, the poses' coordinates)."""
    result, mi, cap = outcome.result, outcome.model_input, outcome.captures
    doc = jsonable(result.report())
    doc["model"] = {"source": mi.label, "sha256": mi.sha256, "tracked_sha256": model_digest(result.model),
                    "vertices": int(result.model.num_vertices), "bones": int(result.model.skeleton.num_bones),
                    "template": bool(result.template)}
    doc["input"] = {"source": cap.label, "frames": int(cap.total), "first_frame": outcome.first_frame,
                    "tracked": int(len(result.poses)), "coordinates": cap.coordinates}
    return doc


def mean_mm(result) -> np.ndarray:
    """Per frame the mean distance (mm) of the data to the tracked model, NaN where none (nobody in view)."""
    return np.array([float(f["mean_mm"]) if f.get("mean_mm") is not None else np.nan for f in result.frames])


def _frames(indices, at_most: int = 8) -> str:
    shown = ", ".join(str(int(i)) for i in list(indices)[:at_most])
    return shown + (", …" if len(indices) > at_most else "")


def summary_text(outcome) -> str:
    """One line: frames tracked (input frame indices) and by which tracker, their mean distance to the
    model, re-initialised, doubtful, lost and empty frames (input frame indices), parts out of view, the
    model; the solver's notes are reported separately."""
    result, first = outcome.result, outcome.first_frame
    n = len(result.poses)
    status = [f["status"] for f in result.frames]
    good = sum(s in ("tracked", "limbs searched", "initialised") for s in status)
    parts = [f"{good} of {n} frame{'s' if n != 1 else ''} tracked (input frames {first}..{first + n - 1}) by the "
             f"{result.options.tracker.upper()} depth tracker"]
    dist = mean_mm(result)
    if np.isfinite(dist).any():
        parts.append(f"mean distance to the model {np.nanmedian(dist):.1f} mm (median over frames; worst "
                     f"frame {np.nanmax(dist):.1f} mm)")
    for kind, text in (("initialised", "started anew"), ("limbs searched", "with the limbs searched again"),
                       ("doubtful", "doubtful (the fit fails the checks; see the notes)"),
                       ("lost", "lost (last pose kept)"), ("no person", "with nobody in view (last pose kept)"),
                       ("partly out of view", "partly out of view before a start (last pose kept)")):
        which = [first + k for k, s in enumerate(status) if s == kind]
        if which:
            parts.append(f"{len(which)} frame{'s' if len(which) != 1 else ''} {text} (input frame"
                         f"{'s' if len(which) != 1 else ''} {_frames(which)})")
    held = {}
    for f in result.frames:
        for p in f.get("out_of_view", ()):
            held[p] = held.get(p, 0) + 1
    if held:
        parts.append("out of view: " + ", ".join(f"{p} in {k} frame{'s' if k != 1 else ''}" for p, k in held.items()))
    others = sum(1 for f in result.frames if f.get("others"))
    if others:
        parts.append(f"another person in view in {others} frame{'s' if others != 1 else ''}")
    model = outcome.model_input.label
    if result.template and (result.options.adapt_size or result.options.adapt_surface):
        model += " (adapted to the person)"
    parts.append(f"model: {model}")
    return "; ".join(parts)
