"""The solver run of rig learning (no bpy, runs in the job's worker thread): :func:`learn` calls
:func:`solver.learn.pipeline.learn_rig` and turns its ``progress(fraction, stage, objective)`` into the
job's ``progress(fraction, text)``."""
from dataclasses import dataclass, field

import numpy as np

from ...solver.learn.options import LearnOptions
from ...solver.learn.pipeline import learn_rig
from .inputs import LearnInput


@dataclass
class LearnOutcome:
    """What :func:`learn` returns: the input, the solver's result (``model``, ``poses``, ``report``), the
    per-vertex mean distance to the scans in mm ``(V,)`` (the heat map) and the options of the run."""
    input: LearnInput
    result: object
    vertex_error_mm: np.ndarray
    options: LearnOptions = field(default_factory=LearnOptions)

    @property
    def model(self):
        return self.result.model

    @property
    def poses(self):
        return self.result.poses

    @property
    def report(self) -> dict:
        return self.result.report


def learn(inp: LearnInput, options: LearnOptions, progress=None) -> LearnOutcome:
    """Learn a rig from ``inp`` with ``options`` (no bpy).  ``progress(fraction, text)`` may raise
    ``Cancelled``.  The heat map is the solver's distance of every scan vertex to the posed model's
    surface (``LearnResult.scan_distances``) averaged over the scans."""
    def report(fraction, stage, objective=None):
        if progress is not None:
            q = "" if objective is None else f"  Q = {float(objective):.6g}"
            progress(0.95 * float(fraction), f"{stage}{q}")

    result = learn_rig(inp.scans, inp.faces, options, progress=report)
    heat = 1000.0 * result.scan_distances.mean(axis=0)      # the distances the solver's report summarises
    if progress is not None:
        progress(1.0, "done")
    return LearnOutcome(inp, result, heat, options)
