"""Tracking a person's model through a sequence of unregistered captures: the stages, top-down.

Model-adaptive mocap dissertation §4.2 (the BUFF pipeline, Fig. 4.8) on the tracking core
(:mod:`solver.tracking`, docs/track.md "Design"):

1. **prior**: the pose prior, learned from the model's own poses, the generic human prior, or none;
   it guides the searched frames (first and lost);
2. **first frame**: the user's start pose, or start hypotheses from a broad pose set in any world
   orientation, each fitted coarse-to-fine; the best covering fit wins (:mod:`.first_frame`);
3. **adaptation** (when on): the model's rest shape and joints refined on key frames (:mod:`.adapt`);
4. **pass 1**: every frame from its constant-velocity prediction (:mod:`.follow`); jumps are searched
   again and lost frames listed; frames with too few points skipped;
5. **windows**: overlapping windows of frames fitted together with a temporal term
   (:mod:`solver.tracking.window`), so a frame's pose depends on its neighbours' data only;
6. **gaps**: skipped and lost frames interpolated between their tracked neighbours;
7. **report**: per frame the capture-to-model distances and the truth-free checks
   (:mod:`solver.tracking.checks`): frames whose fit is wrong though its residual is low are reported
   doubtful or lost.

Units: metres; poses in the captures' coordinates, one per input frame of the range.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import ArticulaInputError
from ..parallel import single_blas_thread, using
from ..rig.model import Model, Poses
from ..tracking.body import Body
from ..tracking.checks import prepare
from ..tracking.frame import SEARCH, SEARCH_HOLD, FrameSettings, fit_frame
from ..tracking.lm import State
from ..tracking.pose_prior import PosePrior, generic_prior, widened
from ..tracking.priors import PairPrior
from ..tracking.window import fit_windows
from .adaptation import SHAPE_OFF, adapt_on_keys, model_offset
from .first_frame import as_start, check_units, find_pose
from .follow import follow, median_mm
from .gaps import interpolate_gaps, stacked
from .options import ADAPT_MIN_FRAMES, MODEL_PRIOR_MIN_POSES, TrackOptions
from .recording import Recording
from .trail import Resume, Trail
from .report import adapt_note, assess, notes

BOX_PAD = 0.1           # rad added to each side of the prior's box limits
PRIOR_WEIGHT = 1e-5     # weight of the pairwise pose prior in searched frames (m^2 per unit of Eq. 4.8)


@dataclasses.dataclass
class TrackResult:
    """Result of :func:`track_sequence` (CONTRACT: docs/track.md "Pipeline").  poses: one per tracked
    frame, input order; model: adapted (same bones and vertex order) or the input model; frames: per
    frame ``name, mean_mm, median_mm, mad_mm, iqr_mm, points, lost, skipped, reason, seconds, verdict,
    checks``."""
    poses: Poses
    model: Model
    adapted: bool
    frames: list
    lost: list
    skipped: list
    timings: dict
    prior: str
    first_frame: int
    notes: list = dataclasses.field(default_factory=list)
    doubtful: list = dataclasses.field(default_factory=list)
    pass1: dict = None          # pass 1's state per frame (:meth:`.trail.Trail.arrays`), for resuming

    def report(self) -> dict:
        """JSON-serialisable summary: everything but the poses and the model."""
        med = [f["median_mm"] for f in self.frames if f["median_mm"] is not None]
        return {"format": "articula-track-report/2", "first_frame": self.first_frame, "frames": self.frames,
                "lost_frames": self.lost, "skipped_frames": self.skipped, "doubtful_frames": self.doubtful,
                "adapted": self.adapted, "prior": self.prior, "timings_s": self.timings, "notes": self.notes,
                "median_mm": float(np.median(med)) if med else None}


def track_sequence(model, source, options: TrackOptions = TrackOptions(), training_poses: Poses = None,
                   progress=None, start_pose: Poses = None, resume: Resume = None) -> TrackResult:
    """Track ``model`` through ``source`` (a :class:`.captures.CaptureSource`, thinned to
    ``options.max_points``, or any indexable sequence of captures with ``points``/``normals``), module
    docstring.  training_poses: the model's poses (prior); start_pose: the first frame's start (one
    frame) instead of the search; resume: pass 1's state another run of the same input and model left
    (:mod:`.trail`): when it is this run's first frame's, pass 1 goes on from it as that run did, else
    its pose is the start pose; progress: ``progress(fraction, text)``, may raise
    :class:`..errors.Cancelled`."""
    options.validate()
    model.validate()
    with single_blas_thread(), using(options.workers):
        clock, say = Clock(), Progress(progress)
        rec = Recording(source, options)
        prior, prior_name = clock.run("prior", choose_prior, model, training_poses, options.prior)
        body = Body(model)
        settings = FrameSettings(samples=options.samples, weak_ratio=options.weak_ratio)
        priors = [PairPrior(prior, PRIOR_WEIGHT)] if prior is not None else []
        checked = prepare(model) if options.checks else None
        resumed = resumable(resume, rec)
        if resumed is None and resume is not None and start_pose is None:
            start_pose = resume.pose
        first, pose = clock.run("initialisation", first_frame, body, rec, start_pose, priors, options, settings,
                                checked, resumed)
        trail = Trail(len(rec), model.skeleton.num_bones)
        tracked = lambda i, med: say(0.6 * (i + 1) / len(rec), f"tracking: frame {i + 1} of {len(rec)}, median "
                                                               f"{med:.1f} mm")
        tracked(first, rec.entries[first]["median_mm"])
        poses = clock.run("pass 1", follow, body, rec, first, pose, options, settings, priors, tracked,
                          None, checked, resumed, trail)
        adapted, offset = adapting(options, rec, body, poses)
        if adapted:
            body, poses = clock.run("adaptation", adapt_on_keys, body, rec, poses, prior, training_poses, options,
                                    settings, say)
        if options.temporal and len(poses) >= 3:
            poses = clock.run("windows", smooth, body, rec, poses, options, settings, say)
        full = interpolate_gaps(stacked(poses, len(rec)), rec.usable())
        doubtful = clock.run("report", assess, body, rec, full, checked)
    lost = [rec.range[i] for i in range(len(rec)) if rec.entries[i]["lost"]]
    skipped = [rec.range[i] for i in range(len(rec)) if rec.entries[i]["skipped"]]
    said = notes(rec, prior_name, options, doubtful) + adapt_note(rec, offset, adapted) + resumed_note(resumed)
    return TrackResult(full, body.model, adapted, rec.entries, lost, skipped, clock.rounded(), prior_name,
                       rec.range.start, said, doubtful, trail.arrays())


def choose_prior(model, training_poses, which: str):
    """``(PosePrior or None, name)`` for ``which`` ("auto", "model", "generic", "none")."""
    have = 0 if training_poses is None else len(training_poses)
    if which == "auto":
        which = "model" if have >= MODEL_PRIOR_MIN_POSES else "generic"
    if which == "none":
        return None, "none"
    if which == "model":
        if have < MODEL_PRIOR_MIN_POSES:
            raise ArticulaInputError(f"prior 'model': the model has {have} pose(s), at least "
                                     f"{MODEL_PRIOR_MIN_POSES} are needed (use the generic prior)")
        own = PosePrior.from_poses(model.skeleton, training_poses, k_max=4)
        return widened(own, generic_prior(model.skeleton), BOX_PAD), "model"
    return widened(generic_prior(model.skeleton), None, BOX_PAD), "generic"


def resumable(resume, rec):
    """``resume`` when it is the state after this run's first input frame (same number, and same name
    when it names one) and that frame has enough points, else None."""
    if resume is None or resume.input_frame != rec.range.start:
        return None
    rec.capture(0)
    if resume.frame_name and rec.entries[0]["name"] != resume.frame_name:
        return None                   # another recording: its pose is a start pose
    return None if rec.too_few(0) else resume


def resumed_note(resumed) -> list:
    if resumed is None:
        return []
    return [f"pass 1 went on from the state another run left after input frame {resumed.input_frame} (its pose, "
            f"velocity and running medians)"]


def first_frame(body, rec, start_pose, priors, options, settings, checked=None, resume=None):
    """``(tracked frame, pose)`` of the first frame with enough points: ``resume``'s pose (another run's
    pass-1 pose of it, kept as it is), fitted from ``start_pose`` or found by the search."""
    for i in range(len(rec)):
        t0 = time.perf_counter()
        capture = rec.capture(i)
        if rec.too_few(i):
            continue
        check_units(body.model, capture.points)
        if resume is not None:
            rec.entries[i].update(median_mm=median_mm(State(body, resume.pose), capture.points))
            return i, resume.pose
        if start_pose is not None:
            fit = fit_frame(body, capture.points, capture.normals, as_start(body.model, start_pose),
                            priors=priors, stages=SEARCH, settings=settings, weak_ratio=SEARCH_HOLD)
            pose = fit.pose
        else:
            pose, _, _ = find_pose(body, capture, priors, count=options.hypotheses, settings=settings,
                                   checked=checked)
        rec.entries[i].update(seconds=round(time.perf_counter() - t0, 3),
                              median_mm=median_mm(State(body, pose), capture.points))
        return i, pose
    raise ArticulaInputError(f"captures: no frame of the {len(rec)} tracked has at least 100 points "
                             f"(all empty or all NaN)")


def adapting(options, rec, body, poses) -> tuple:
    """``(adapt, offset)``: "on" adapts; "auto" when the model lies more than ``SHAPE_OFF`` off the captures
    at pass 1's poses (``offset``, m: :func:`.adaptation.model_offset`; None unless "auto") and the range has
    at least ``ADAPT_MIN_FRAMES`` frames: another body's model gains 2-3x, the subject's own nothing."""
    if options.adapt != "auto":
        return options.adapt == "on", None
    offset = model_offset(body, rec, poses, options.adapt_every)
    return offset > SHAPE_OFF and len(rec) >= ADAPT_MIN_FRAMES, offset


def smooth(body, rec, poses, options, settings, say):
    """Pass 1's poses refined in overlapping windows with the temporal term."""
    frames = sorted(poses)
    return fit_windows(body, rec, poses, frames, options, settings,
                       lambda f: say(0.6 + 0.35 * f, "temporal pass"))


class Clock:
    """Seconds spent per stage."""

    def __init__(self):
        self.totals = {}

    def run(self, stage, fn, *args):
        t0 = time.perf_counter()
        try:
            return fn(*args)
        finally:
            self.totals[stage] = self.totals.get(stage, 0.0) + time.perf_counter() - t0

    def rounded(self) -> dict:
        return {k: round(v, 3) for k, v in self.totals.items()}


class Progress:
    """``progress(fraction, text)`` or nothing."""

    def __init__(self, progress):
        self.progress = progress

    def __call__(self, fraction, text):
        if self.progress is not None:
            self.progress(min(max(fraction, 0.0), 1.0), text)
