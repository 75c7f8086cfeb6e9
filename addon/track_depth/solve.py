"""The solver run of depth tracking (no bpy, runs in the job's worker thread): :func:`track` calls
:func:`solver.track_depth.pipeline.track_recording` with the model (None: the built-in template body)
and the recording, passing the tracker's "frame i of N" progress on."""
from __future__ import annotations

from dataclasses import dataclass

from ...solver.rig.model import Poses
from ...solver.track_depth.options import DepthTrackOptions
from ...solver.track_depth.pipeline import track_recording
from ..tracking.inputs import ModelInput
from .inputs import DepthCaptures


@dataclass
class DepthOutcome:
    """What :func:`track` returns: the inputs, the options and the solver's :class:`DepthTrackResult`."""
    model_input: ModelInput
    captures: DepthCaptures
    result: object
    options: DepthTrackOptions

    @property
    def model(self):
        """The tracked model: the given one, or the template adapted to the person."""
        return self.result.model

    @property
    def poses(self) -> Poses:
        return self.result.poses

    @property
    def first_frame(self) -> int:
        return int(self.captures.first)

    @property
    def new_model(self) -> bool:
        """True when the tracked model is not the one given (the template, or a model the solver adapted):
        a rig is built from it."""
        return self.model_input.model is None or self.result.model is not self.model_input.model


def track(model_input: ModelInput, captures: DepthCaptures, options: DepthTrackOptions,
          progress=None) -> DepthOutcome:
    """Track ``captures`` with ``model_input``'s model (its ``model`` None: the template).
    ``progress(fraction, text)`` may raise ``Cancelled``."""
    def report(fraction, text=""):
        if progress is not None:
            progress(fraction, text)

    report(0.0, "reading the recording")
    result = track_recording(captures.recording, model_input.model, options.validate(), progress=report)
    report(1.0, "done")
    return DepthOutcome(model_input, captures, result, options)
