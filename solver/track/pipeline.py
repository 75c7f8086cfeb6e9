"""Tracking a person's model through a sequence of unregistered captures: the whole pipeline.

Model-adaptive mocap dissertation §4.2 (the BUFF pipeline, Fig. 4.8), with the automatic first frame
and the lost-frame handling the issue asks for (docs/track.md "Pipeline"):

1. the pose prior: learned from the model's own poses, the shipped generic human prior, or none;
2. the first tracked frame: global alignment and starting hypotheses (:mod:`.initialise`);
3. model adaptation to that frame (when adaptation runs, :mod:`.adapt`);
4. pass 1: every frame from its predecessor's pose (:func:`.frame_fit.fit_frame`, w_temp = 0); a frame
   whose median scan-to-model distance jumps is re-initialised from the hypotheses, and listed as lost
   if that does not bring it back; frames with too few points are skipped;
5. the model refined on every ``adapt_every``-th frame, their poses with it;
6. pass 2: overlapping sliding windows with the temporal prior (:mod:`.windows`), or, without the
   temporal term, every frame refitted with the adapted model;
7. the report: per frame the scan-to-model distances (point to closest triangle, :mod:`.metrics`),
   lost and skipped frames, time per stage.

Skipped and lost frames get the pose interpolated between their tracked neighbours (held at the ends),
so the result has exactly one pose per frame.  Units: metres; poses in the captures' coordinates.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import quat_canonical, quat_mul, quat_conj, quat_normalize, quat_to_rotvec, rotvec_to_quat
from ..parallel import single_blas_thread
from ..rig.model import Model, Poses
from ..rig.skinning import AnchorGroups
from . import metrics, robust
from .adapt import adapt_model, mirror_pairs
from .captures import CaptureSource
from .frame_fit import fit_frame
from .initialise import check_units, initialise
from .options import ADAPT_MIN_FRAMES, MODEL_PRIOR_MIN_POSES, TrackOptions, frame_range
from ..tracking.pose_prior import PosePrior, generic_prior, widened
from .temporal import MotionPrior, motion_weight, temporal_weight
from .windows import fit_windows

MIN_POINTS = 100         # a frame with fewer points (after cleaning) is skipped
BOX_PAD = 0.1           # rad added to each side of the box limits (docs/track.md "Box limits")
RUNNING = 10             # frames in the running median that lost-frame detection compares with


@dataclasses.dataclass
class TrackResult:
    """Result of :func:`track_sequence` (CONTRACT: docs/track.md "Pipeline").  poses: one per tracked
    frame, input order; model: adapted (same bones and vertex order) or the input model; frames: per
    frame ``name, mean_mm, median_mm, mad_mm, iqr_mm, points, lost, skipped, reason, seconds``."""
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

    def report(self) -> dict:
        """JSON-serialisable summary: everything but the poses and the model."""
        med = [f["median_mm"] for f in self.frames if f["median_mm"] is not None]
        return {"format": "articula-track-report/1", "first_frame": self.first_frame, "frames": self.frames,
                "lost_frames": self.lost, "skipped_frames": self.skipped, "adapted": self.adapted,
                "prior": self.prior, "timings_s": self.timings, "notes": self.notes,
                "median_mm": float(np.median(med)) if med else None}


class _Clock:
    """Seconds spent per stage."""

    def __init__(self):
        self.totals = {}

    def add(self, stage, t0):
        self.totals[stage] = self.totals.get(stage, 0.0) + time.perf_counter() - t0


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


def _say(progress, fraction, text):
    if progress is not None:
        progress(min(max(fraction, 0.0), 1.0), text)


def track_sequence(model, source, options: TrackOptions = TrackOptions(), training_poses: Poses = None,
                   progress=None, start_pose: Poses = None) -> TrackResult:
    """Track ``model`` through ``source`` (a :class:`.captures.CaptureSource`, thinned to
    ``options.max_points`` whatever it was made with, or any indexable sequence of
    :class:`.frame_fit.Capture`, used as it is), module docstring.  training_poses: the model's poses (prior and
    hypotheses); start_pose: the first frame's start (one frame) instead of the automatic
    initialisation; progress: ``progress(fraction, text)``, may raise :class:`..errors.Cancelled`."""
    options.validate()
    model.validate()
    with single_blas_thread():
        return _Tracker(model, source, options, training_poses, progress).run(start_pose)


class _Tracker:
    """The state of one :func:`track_sequence` run."""

    def __init__(self, model, source, options, training_poses, progress):
        if isinstance(source, CaptureSource) and source.max_points != options.max_points:
            source = source.with_max_points(options.max_points)      # the options decide the thinning
        self.model, self.source, self.options, self.progress = model, source, options, progress
        self.training = training_poses
        self.range = frame_range(options.frames, len(source))
        self.n = len(self.range)
        self.clock = _Clock()
        self.groups = AnchorGroups(model)
        self.frames = [None] * self.n
        self.captures = {}
        self.q_data = {}         # pass 1's Q^data per tracked frame (m), for the w_temp heuristic
        self.poses_1 = {}        # pass 1's pose per tracked frame, for the motion prior
        self.w_temp = 0.0
        self.sym_pairs = mirror_pairs(model.skeleton)    # of the input model: adapted tails leave their children
        self.adapt = options.adapt == "on" or (options.adapt == "auto" and self.n >= ADAPT_MIN_FRAMES)

    def capture(self, i):
        """The capture of tracked frame i (read once, kept thinned)."""
        if i not in self.captures:
            self.captures[i] = self.source[self.range[i]]
        return self.captures[i]

    def run(self, start_pose):
        t0 = time.perf_counter()
        self.prior, prior_name = choose_prior(self.model, self.training, self.options.prior)
        self.clock.add("prior", t0)
        poses = self.pass_one(start_pose)
        adapted = False
        if self.adapt:
            poses, adapted = self.adapt_model(poses), True
        if self.n >= 3 and (self.options.temporal or adapted):
            poses = self.pass_two(poses)
        poses = self.fill_gaps(poses)
        self.final_stats(poses)
        lost = [self.range[i] for i in range(self.n) if self.frames[i]["lost"]]
        skipped = [self.range[i] for i in range(self.n) if self.frames[i]["skipped"]]
        notes = self.notes(prior_name)
        return TrackResult(poses, self.model, adapted, self.frames, lost, skipped,
                           {k: round(v, 3) for k, v in self.clock.totals.items()}, prior_name, self.range.start,
                           notes)

    def notes(self, prior_name):
        out = []
        if prior_name == "generic":
            out.append("pose prior: the generic human prior (the model has fewer than "
                       f"{MODEL_PRIOR_MIN_POSES} poses of its own)" if self.options.prior == "auto"
                       else "pose prior: the generic human prior")
        poor = [self.range[i] for i, f in enumerate(self.frames)
                if not f["skipped"] and f["median_mm"] is not None and f["median_mm"] > self.options.poor_fit_mm]
        if poor:
            out.append(f"poor fit: {len(poor)} frame(s) have a median scan-to-model distance above "
                       f"{self.options.poor_fit_mm:g} mm (first: frame {poor[0]}); is it the same person and "
                       f"the right model?")
        return out

    # pass 1 -----------------------------------------------------------------------------------------

    def pass_one(self, start_pose):
        """Frames in order, each from the last good pose; returns ``(n, ...)`` Poses with NaN-free
        placeholders (the last good pose) for skipped frames."""
        rot, trans, scale = [], [], []
        pose, history = None, []
        for i in range(self.n):
            t0 = time.perf_counter()
            capture = self.capture(i)
            self.frames[i] = self._frame_entry(i, capture)
            if len(capture.points) < MIN_POINTS:
                self.frames[i].update(skipped=True, reason=f"{len(capture.points)} points (fewer than {MIN_POINTS})")
            elif pose is None:
                pose = self._first(i, capture, start_pose)
                history.append(self.frames[i]["median_mm"])
            else:
                pose = self._next(i, capture, pose, history)
            self.frames[i]["seconds"] = round(time.perf_counter() - t0, 3)
            self.clock.add("pass 1", t0)
            if pose is not None:
                rot.append(pose.rotations[0]), trans.append(pose.translations[0]), scale.append(pose.scales[0])
            else:
                rot.append(None), trans.append(None), scale.append(None)
            _say(self.progress, 0.5 * (i + 1) / self.n, self._text("tracking", i))
        if pose is None:
            raise ArticulaInputError(f"captures: no frame of the {self.n} tracked has at least {MIN_POINTS} "
                                     f"points (all empty or all NaN)")
        first = next(k for k, r in enumerate(rot) if r is not None)
        for k in range(first):
            rot[k], trans[k], scale[k] = rot[first], trans[first], scale[first]
        return Poses(np.array(rot), np.array(trans), np.array(scale))

    def _frame_entry(self, i, capture):
        names = getattr(self.source, "names", None)
        info = self.source.info(self.range[i]) if hasattr(self.source, "info") else None
        return {"frame": self.range[i], "name": names[self.range[i]] if names else str(self.range[i]),
                "points": int(len(capture.points)), "dropped_nan": int(info.dropped_nan) if info else 0,
                "mean_mm": None, "median_mm": None, "mad_mm": None, "iqr_mm": None,
                "lost": False, "skipped": False, "reinitialised": False, "reason": "", "seconds": 0.0}

    def _text(self, what, i):
        med = self.frames[i].get("median_mm")
        tail = f", median {med:.1f} mm" if med is not None else ""
        return f"{what}: frame {i + 1} of {self.n}{tail}"

    def _first(self, i, capture, start_pose):
        """Pose of the first usable frame i: from ``start_pose`` or the hypotheses; the model adapted to
        it when adaptation runs (§4.2 step 2)."""
        t0 = time.perf_counter()
        check_units(self.model, capture.points)
        if start_pose is not None:
            fit = fit_frame(self.model, capture, start_pose, self.prior, self.options.frame, self.groups)
        else:
            fit = initialise(self.model, capture, self.prior, self.training, self.options.frame, self.groups,
                             count=self.options.hypotheses).fit
        self.clock.add("initialisation", t0)
        pose = fit.pose
        if self.adapt:
            pose = self._adapt([i], pose, "adapting the model to the first frame")
            fit = fit_frame(self.model, capture, pose, self.prior, self.options.frame, self.groups)
            pose = fit.pose
        self.frames[i]["median_mm"] = fit.stats["median_mm"]
        self.q_data[i] = float(fit.log["data"].min())
        self.poses_1[i] = pose
        return pose

    def _next(self, i, capture, pose, history):
        """Frame i from the last good ``pose``, held near it by the motion prior (a constant-velocity
        prediction measured no better: docs/track.md); re-initialised when its median jumps (lost-frame detection)."""
        motion = self._motion_prior(i)
        fit = fit_frame(self.model, capture, pose, self.prior, self.options.frame, self.groups, motion)
        median = fit.stats["median_mm"]
        limit = max(self.options.lost_factor * float(np.median(history[-RUNNING:])), self.options.lost_mm)
        if median > limit:
            t0 = time.perf_counter()
            again = initialise(self.model, capture, self.prior, self.training, self.options.frame, self.groups,
                               count=self.options.hypotheses, extra=[pose], check=False)
            self.clock.add("re-initialisation", t0)
            self.frames[i]["reinitialised"] = True
            if again.fit.stats["median_mm"] < median:
                fit, median = again.fit, again.fit.stats["median_mm"]
            if median > limit:
                self.frames[i].update(lost=True, reason=f"median {median:.1f} mm after re-initialisation "
                                                        f"(limit {limit:.1f} mm)")
                self.frames[i]["median_mm"] = median
                return pose
        self.frames[i]["median_mm"] = median
        self.q_data[i] = float(fit.log["data"].min())
        self.poses_1[i] = fit.pose
        history.append(median)
        return fit.pose

    def _motion_prior(self, i):
        """Pass 1's :class:`.temporal.MotionPrior` for frame i: towards frame i−1's pose, weighted by
        :func:`.temporal.motion_weight` from frames i−2 and i−1 (None unless both were tracked)."""
        share = self.options.w_motion
        if not share or i < 2 or not {i - 1, i - 2} <= set(self.q_data):
            return None
        previous = np.stack([self.poses_1[i - 2].rotations[0], self.poses_1[i - 1].rotations[0]])
        return MotionPrior(previous[1:], motion_weight(share, self.q_data[i - 1], previous))

    # adaptation and pass 2 ------------------------------------------------------------------------

    def usable(self):
        return [i for i in range(self.n) if not (self.frames[i]["skipped"] or self.frames[i]["lost"])]

    def adapt_model(self, poses):
        """The model refined on every ``adapt_every``-th usable frame (at least 3 when there are), those
        frames' poses refined with it (§4.1.4 (d), §4.2 step 4)."""
        usable = self.usable()
        keys = usable[::self.options.adapt_every]
        if len(keys) < 3:
            keys = [usable[k] for k in np.unique(np.linspace(0, len(usable) - 1, min(3, len(usable))).astype(int))]
        return _put(poses, keys, self._adapt(keys, poses.take(keys), "adapting the model", 0.5, 0.15))

    def _adapt(self, keys, key_poses, what, lo=0.0, span=0.0):
        """Adapt the model to the tracked frames ``keys`` at ``key_poses``; returns their refined poses."""
        t0 = time.perf_counter()
        caps = [self.capture(i) for i in keys]
        report = lambda f, text: _say(self.progress, lo + span * f, f"{what}: {text}")
        out = adapt_model(self.model, caps, key_poses, self.prior, groups=self.groups, progress=report,
                          training_poses=self.training, sym_pairs=self.sym_pairs)
        self.model, self.groups = out.model, AnchorGroups(out.model)
        self.clock.add("adaptation", t0)
        return out.poses

    def pass_two(self, poses):
        """Sliding windows with the temporal prior (or, with ``temporal`` off, every frame refitted)."""
        t0 = time.perf_counter()
        usable = self.usable()
        if self.options.temporal:
            start = poses.take(usable)
            self.w_temp = self.options.w_temp or temporal_weight(
                [self.q_data[i] for i in usable if i in self.q_data] or [robust.EPS_M], start.rotations)
            report = lambda f, text: _say(self.progress, 0.65 + 0.3 * f, f"temporal pass: {text}")
            sub, _ = fit_windows(self.model, _Subset(self, usable), start, self.prior, self.w_temp,
                                 self.options.frame, progress=report, size=self.options.window,
                                 step=self.options.step)
            poses = _put(poses, usable, sub)
        else:
            for k, i in enumerate(usable):
                fit = fit_frame(self.model, self.capture(i), poses.take(i), self.prior, self.options.frame,
                                self.groups)
                poses = _put(poses, [i], fit.pose)
                _say(self.progress, 0.65 + 0.3 * (k + 1) / len(usable), self._text("refitting", i))
        self.clock.add("pass 2", t0)
        return poses

    def fill_gaps(self, poses):
        """Skipped and lost frames: the pose interpolated between the nearest usable frames."""
        usable = self.usable()
        return interpolate_gaps(poses, usable)

    def final_stats(self, poses):
        """Per usable frame: scan-point-to-model distances (point to closest triangle), mm."""
        from ..rig.skinning import hybrid_skin
        t0 = time.perf_counter()
        for i in self.usable():
            posed = hybrid_skin(self.model, poses.take(i), self.groups)[0]
            d = metrics.point_to_mesh(self.capture(i).points, posed, self.model.faces) * 1e3
            stats = metrics.robust_stats(d)
            self.frames[i].update(mean_mm=stats["mean"], median_mm=stats["median"], mad_mm=stats["mad"],
                                  iqr_mm=stats["iqr"])
        self.clock.add("report", t0)


class _Subset:
    """The tracker's captures of the frames ``index`` as an indexable sequence."""

    def __init__(self, tracker, index):
        self.tracker, self.index = tracker, list(index)

    def __len__(self):
        return len(self.index)

    def __getitem__(self, k):
        return self.tracker.capture(self.index[k])


def _put(poses, index, part) -> Poses:
    out = poses.take(slice(None))
    out.rotations[list(index)] = part.rotations
    out.translations[list(index)] = part.translations
    out.scales[list(index)] = part.scales
    return out


def interpolate_gaps(poses, usable) -> Poses:
    """``poses`` with every frame not in ``usable`` replaced by the interpolation between the nearest
    usable frames before and after (rotations: per bone along the geodesic; translation, scale:
    linear); held at the ends."""
    out = poses.take(slice(None))
    usable = sorted(usable)
    if not usable:
        return out
    for i in range(len(poses)):
        if i in usable:
            continue
        k = np.searchsorted(usable, i)
        a = usable[max(k - 1, 0)]
        b = usable[min(k, len(usable) - 1)]
        w = 0.0 if a == b else (i - a) / (b - a)
        qa, qb = poses.rotations[a], poses.rotations[b]
        qb = np.where((np.sum(qa * qb, axis=-1) < 0)[:, None], -qb, qb)
        rel = quat_to_rotvec(quat_mul(quat_conj(qa), qb))
        out.rotations[i] = quat_canonical(quat_normalize(quat_mul(qa, rotvec_to_quat(w * rel))))
        out.translations[i] = (1 - w) * poses.translations[a] + w * poses.translations[b]
        out.scales[i] = (1 - w) * poses.scales[a] + w * poses.scales[b]
    return out
