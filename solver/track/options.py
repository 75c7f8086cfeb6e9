"""Settings of tracking a model through unregistered captures (:func:`.pipeline.track_sequence`): every
default once, read by the solver, the ``articula.track`` operator and the ``track`` batch command."""
from __future__ import annotations

import dataclasses

from ..errors import ArticulaInputError

ADAPT_CHOICES = ("auto", "on", "off")
PRIOR_CHOICES = ("auto", "model", "generic", "none")
ADAPT_MIN_FRAMES = 10        # "auto" adapts a model off the captures when the range has at least this many frames
MODEL_PRIOR_MIN_POSES = 3    # "auto" learns the prior from the model's own poses when it has this many


@dataclasses.dataclass(frozen=True)
class TrackOptions:
    """adapt: refine the rest mesh and joints from the recording ("auto": when the model's surface lies off
    the captures beyond their noise, :func:`.adaptation.shape_offset`, and the range has at least
    ``ADAPT_MIN_FRAMES`` frames: another body's model, not the subject's own); adapt_every: the model is refined on every this many-th tracked frame
    (dissertation §4.2: every 25th); temporal: the sliding-window pass (``window`` frames, ``step``,
    temporal weight ``w_temp`` per frame and rad^2, relative to the data's normal matrix); prior: which
    pose prior ("auto": the model's own poses when it has ``MODEL_PRIOR_MIN_POSES``, else the generic
    human prior; it guides the first frame and re-initialised frames); fit_scale: also fit one uniform
    scale on the first frame; frames: ``(a, b)`` tracks input frames a..b-1 only (None: all);
    max_points: captures are thinned to about this many points (0: never); samples: capture points
    fitted per frame (a fixed seeded sample); weak_ratio: directions whose data curvature is below this
    share of the largest are held to a prediction carrying on half the last frame's motion
    (:func:`solver.tracking.priors.weak_directions`, :data:`.follow.HOLD_CARRY`);
    hypotheses: start poses refined on the first frame and on lost frames; lost_factor, lost_mm: a frame
    whose median capture-to-model distance exceeds both ``lost_factor`` times the running median and
    ``lost_mm`` is re-initialised, and lost if that does not help; poor_fit_mm: a median above it is
    reported as a poor fit; checks: the truth-free checks of every frame (:mod:`solver.tracking.checks`);
    workers: threads for the fits that do not depend on each other (the first frame's start hypotheses, a
    window's frames, the report's frames; 0: one per CPU core); the result does not depend on it."""
    adapt: str = "auto"
    adapt_every: int = 25
    temporal: bool = True
    window: int = 9
    step: int = 4
    w_temp: float = 1e-4
    prior: str = "auto"
    fit_scale: bool = False
    frames: tuple = None
    max_points: int = 20_000
    samples: int = 4000
    weak_ratio: float = 1e-5
    hypotheses: int = 4
    lost_factor: float = 3.0
    lost_mm: float = 15.0
    poor_fit_mm: float = 10.0
    checks: bool = True
    workers: int = 0

    def validate(self) -> "TrackOptions":
        """Raise :class:`ArticulaInputError` naming the first setting out of range; returns self."""
        if self.adapt not in ADAPT_CHOICES:
            raise ArticulaInputError(f"adapt: expected one of {', '.join(ADAPT_CHOICES)}, got {self.adapt!r}")
        if self.prior not in PRIOR_CHOICES:
            raise ArticulaInputError(f"prior: expected one of {', '.join(PRIOR_CHOICES)}, got {self.prior!r}")
        for name, lo, hi in (("adapt_every", 1, 10_000), ("window", 3, 101), ("hypotheses", 1, 64),
                             ("max_points", 0, 10_000_000), ("samples", 200, 1_000_000), ("workers", 0, 1024)):
            value = getattr(self, name)
            if int(value) != value or not lo <= value <= hi:
                raise ArticulaInputError(f"{name}: expected a whole number in {lo}..{hi}, got {value}")
        if not 1 <= self.step < self.window:
            raise ArticulaInputError(f"step: expected 1..{self.window - 1} (less than the window), got {self.step}")
        if 0 < self.max_points < 500:
            raise ArticulaInputError(f"max_points: {self.max_points} is too few to track a body (at least 500, "
                                     f"or 0 to keep every point)")
        for name in ("w_temp", "weak_ratio", "lost_factor", "lost_mm", "poor_fit_mm"):
            value = getattr(self, name)
            if not (value == value and 0 <= value < 1e12):
                raise ArticulaInputError(f"{name}: expected a finite value >= 0, got {value}")
        if self.frames is not None:
            a, b = self.frames
            if not (int(a) == a and int(b) == b and 0 <= a < b):
                raise ArticulaInputError(f"frames: expected A:B with 0 <= A < B, got {a}:{b}")
        return self


def frame_range(frames, count: int) -> range:
    """The input frames to track: ``frames`` ``(a, b)`` (b clipped to ``count``) or all ``count``."""
    if count == 0:
        raise ArticulaInputError("captures: no frames to track")
    if frames is None:
        return range(count)
    a, b = int(frames[0]), int(frames[1])
    if a >= count:
        raise ArticulaInputError(f"frames: {a}:{b} starts after the last frame ({count} frames, numbered from 0)")
    return range(a, min(b, count))
