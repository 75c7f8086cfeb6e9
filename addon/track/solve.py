"""The solver run of tracking (no bpy, runs in the job's worker thread): :func:`track` calls
:func:`solver.track.pipeline.track_sequence` with the model and the captures, then measures every capture
point's distance to the tracked (adapted) model on its frame, which the error colours show."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...solver.rig.model import Poses
from ...solver.rig.skinning import hybrid_skin
from ...solver.track.metrics import point_to_mesh
from ...solver.track.options import TrackOptions
from ...solver.track.pipeline import track_sequence
from .inputs import CaptureInput, ModelInput

TRACK_SHARE = 0.9      # of the progress bar: the tracker; the rest: the per-point distances


@dataclass
class TrackOutcome:
    """What :func:`track` returns: the inputs, the solver's :class:`TrackResult`, the options, and per
    tracked frame the distance (mm) of every capture point to the tracked model (capture vertex order;
    NaN for a point with a non-finite coordinate), or None when not asked for."""
    model_input: ModelInput
    captures: CaptureInput
    result: object
    options: TrackOptions = field(default_factory=TrackOptions)
    point_errors_mm: list = None

    @property
    def model(self):
        return self.result.model

    @property
    def poses(self) -> Poses:
        return self.result.poses

    @property
    def first_frame(self) -> int:
        return int(self.result.first_frame)


def point_errors(model, poses: Poses, captures: CaptureInput, first_frame: int, progress=None) -> list:
    """Distances (mm, float32) of each tracked frame's capture points to the model posed for that frame."""
    out = []
    for j in range(len(poses)):
        pts, _ = captures.reader(first_frame + j)
        one = poses.take(j)
        posed = hybrid_skin(model, one)[0]
        d = np.full(len(pts), np.nan, np.float32)
        good = np.isfinite(pts).all(axis=1)
        if good.any():
            d[good] = 1000.0 * point_to_mesh(pts[good], posed, model.faces)
        out.append(d)
        if progress is not None:
            progress(TRACK_SHARE + (1 - TRACK_SHARE) * (j + 1) / len(poses),
                     f"error colours: frame {j + 1} of {len(poses)}")
    return out


def track(model_input: ModelInput, captures: CaptureInput, options: TrackOptions, progress=None,
          with_point_errors: bool = True) -> TrackOutcome:
    """Track ``captures`` with ``model_input``'s model (no bpy).  ``progress(fraction, text)`` may raise
    ``Cancelled``; the tracker's own text (frame i of N, residual) is passed on."""
    share = TRACK_SHARE if with_point_errors else 1.0

    def report(fraction, text=""):
        if progress is not None:
            progress(share * float(fraction), text)

    source = captures.source(options.max_points)
    result = track_sequence(model_input.model, source, options, training_poses=model_input.training_poses,
                            progress=report, start_pose=model_input.start_pose, resume=model_input.resume)
    errors = None
    if with_point_errors:
        errors = point_errors(result.model, result.poses, captures, int(result.first_frame), progress)
    if progress is not None:
        progress(1.0, "done")
    return TrackOutcome(model_input, captures, result, options, errors)
