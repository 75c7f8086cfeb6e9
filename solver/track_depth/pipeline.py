"""Tracking a depth recording frame by frame (depth-camera tracking dissertation ch. 5, Algorithm 1, and
ch. 6): the first frame (and every frame after the person was lost or out of view) starts from the pose
hypotheses of :mod:`.initialise`; the others from the previous pose.  A frame whose fit leaves more than
``1 - lost_share`` of the observed points unexplained is re-initialised, and reported lost when that does
not help; frames with nobody in view are reported and keep the last pose.  With the built-in template
the body's size and surface adapt over the first frames (:mod:`.adapt`).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from .. import parallel
from ..errors import ArticulaInputError
from ..rig.model import Model, Poses
from ..tracking.blend_body import BlendBody
from ..tracking.motion import extrapolate
from ..tracking.priors import generic_limits
from .adapt import TemplateAdaptation
from .initialise import cut_edges, initialise, score
from .limb_search import place_limbs
from .options import DepthTrackOptions
from .out_of_view import Parts
from .smoothing import FOLLOWED, smooth
from .standing import Standing
from .template import load_template
from .trackers import frame_fitter


@dataclasses.dataclass
class DepthTrackResult:
    """``model`` tracked (the given one or the adapted template), ``poses`` one per frame, ``frames``
    per-frame dicts (name, status, pairs, edges, iterations, near_share, mean_mm, ms; out_of_view,
    findings, others when there are), ``notes``, ``options``, ``template`` (True when the built-in body
    was used), ``seconds`` by stage.  The report's ``frames_per_second`` is the tracking rate of the frames
    tracked from the frame before; ``start_ms`` the mean time of a start (first frame, new starts)."""
    model: Model
    poses: Poses
    frames: list
    notes: list
    options: DepthTrackOptions
    template: bool
    seconds: dict

    def report(self) -> dict:
        status = [f["status"] for f in self.frames]
        tracked = [f for f in self.frames if f["status"] in ("tracked", "limbs searched", "initialised")]
        status_counts = {s: status.count(s) for s in sorted(set(status))}
        ms = [f["ms"] for f in self.frames if f["status"] == "tracked"]       # from the frame before
        starts = [f["ms"] for f in self.frames if f["status"] == "initialised"]
        return {
            "format": "articula-depth-track-report/1", "tracker": self.options.tracker,
            "template": self.template, "frames": len(self.frames),
            "tracked": len(tracked), "lost": status.count("lost"), "no_person": status.count("no person"),
            "initialised": status.count("initialised"), "limbs_searched": status.count("limbs searched"),
            "partly_out_of_view": status.count("partly out of view"), "doubtful": status.count("doubtful"),
            "parts_out_of_view": _part_frames(self.frames),
            "others_in_view": [f["frame"] for f in self.frames if f.get("others")], "statuses": status_counts,
            "frames_per_second": 1000.0 / float(np.mean(ms)) if ms else 0.0,
            "start_ms": float(np.mean(starts)) if starts else None,
            "median_mean_mm": float(np.median([f["mean_mm"] for f in tracked])) if tracked else None,
            "seconds": self.seconds, "notes": self.notes, "options": dataclasses.asdict(self.options),
            "per_frame": self.frames,
        }


def _part_frames(frames) -> dict:
    """``{part name: frames it was out of view}``."""
    out = {}
    for f in frames:
        for part in f.get("out_of_view", ()):
            out[part] = out.get(part, 0) + 1
    return out


PERSON_WORDS = {"centre": "nearest the image's centre", "nearest": "nearest the camera", "largest": "largest in view",
                "left": "leftmost in the image", "right": "rightmost in the image"}


def frame_notes(frames, person: str) -> list:
    """The report's notes on what the frames saw: other people, parts out of view, doubtful fits."""
    notes = []
    others = [f["name"] for f in frames if f.get("others")]
    if others:
        notes.append(f"another person or person-sized object was in view in {len(others)} frame"
                     f"{'s' if len(others) != 1 else ''} ({', '.join(others[:4])}{', ...' if len(others) > 4 else ''}):"
                     f" the person {PERSON_WORDS[person]} was tracked from the start and followed")
    parts = _part_frames(frames)
    if parts:
        notes.append("out of the camera's view, not tracked (a leg is held straight): "
                     + ", ".join(f"{p} ({n} frame{'s' if n != 1 else ''})" for p, n in parts.items()))
    doubtful = [f for f in frames if f["status"] == "doubtful"]
    if doubtful:
        notes.append(f"{len(doubtful)} frame{'s' if len(doubtful) != 1 else ''} doubtful (the fit fails the checks "
                     "of a standing person): " + "; ".join(f"{f['name']}: {', '.join(f['findings'])}"
                                                           for f in doubtful[:4]))
    return notes


def _entry(k, name, status, fit=None, ms=0.0):
    e = {"frame": k, "name": name, "status": status, "ms": round(ms, 2)}
    if fit is not None:
        e.update(pairs=int(fit.pairs), edges=int(fit.edges), iterations=int(fit.iterations),
                 near_share=round(fit.near_share, 4), mean_mm=round(1000 * fit.mean_m, 2))
    return e


RECENT = 15       # frames whose typical explained share sets the limb-search threshold
LIMB_DROP = 0.03  # share below the typical one at which the limbs are searched again
PREDICTION_GAIN = 0.5   # share of the last frame-to-frame change carried into the GMM tracker's prediction
LOST_DROP = 0.25  # share below the typical one at which the frame is lost (and started anew)
CHECK_SLACK = 0.01   # share a fit with fewer findings may explain less than the one it replaces


class _Sequence:
    """The state of one tracking run (see :func:`track_recording`)."""

    def __init__(self, recording, model, options, limits, progress, template=None):
        self.rec, self.opts, self.progress = recording, options, progress
        self.model = model
        self.body = BlendBody(model, count=options.model_points)
        self.adaptation = (TemplateAdaptation(template, options, recording.options, recording.camera.centre)
                           if template is not None else None)
        self.limits = list(limits) if limits is not None else [generic_limits(model.skeleton)]
        self.poses, self.frames = [], []          # the run appends to both
        self.pose = None
        self.lost = False
        self.fit = frame_fitter(options)
        self.parts = Parts(self.body)
        self.standing = Standing(self.body, self.parts)
        self.up = recording.up()                  # the recording is prepared: its floor is known

    def step(self, k, obs):
        name = self.rec.names[k]
        t0 = time.perf_counter()
        if obs.empty:
            self.lost = True
            return _entry(k, name, "no person")
        starting = self.pose is None or self.lost
        if starting and any(cut_edges(obs, sides=True)[2:]):
            return _entry(k, name, "partly out of view")     # no start from half a person: wait for all of it
        if self.adaptation is not None and self.pose is None and self.adaptation.done == 0:
            self.body = BlendBody(self.adaptation.start_model(obs, self.up), ids=self.body.ids)
        if starting:
            fit, status = self._initialise(obs), "initialised"
        else:
            fit, status = self._track(obs)
        fit, status, findings, falls = self._stands(obs, fit, status)
        if self.adaptation is not None and not self._is_lost(fit) and not falls:
            fit = self._adapt(k, obs, fit)
        self.lost = self._is_lost(fit)
        if self.lost:
            status = "lost"
        self.pose = fit.pose
        entry = _entry(k, name, status, fit, 1000 * (time.perf_counter() - t0))
        if obs.others:
            entry["others"] = len(obs.others)
        held = self.parts.out_of_view(self.body, fit.pose, self.rec.camera)[0]
        if held:
            entry["out_of_view"] = held
        if findings:
            entry["findings"] = findings
        return entry

    def _held(self, pose):
        """``(held bones, pose, limits)``: the parts of ``pose`` out of view set where they are held and
        the joint limits holding them (:meth:`.out_of_view.Parts.hold`)."""
        return self.parts.hold(self.body, pose, self.rec.camera, self.limits)

    def _stands(self, obs, fit, status):
        """``(fit, status, findings, falls)`` after the checks (:mod:`.standing`): a fit that does not stand is
        started anew (unless it just was) and replaced when the new start stands better and explains the
        frame as well; parts the camera sees through are reported, not searched again (a new limb search
        explains the same points with other wrong limbs as often as it fixes one: docs/track_depth.md);
        ``doubtful`` when findings remain; ``falls`` when it still does not stand."""
        found = self._findings(obs, fit)
        if found[0] and status != "initialised" and not any(cut_edges(obs, sides=True)[2:]):
            fit, status, found = self._better(obs, fit, status, found, (self._initialise(obs), "initialised"))
        findings = found[0] + found[1]
        return fit, ("doubtful" if findings else status), findings, bool(found[0])

    def _findings(self, obs, fit) -> tuple:
        return self.standing.findings(self.body, fit.pose, obs, self.rec.camera, self.up, fit.posed)

    def _better(self, obs, fit, status, found, candidate):
        """The candidate ``(fit, status)`` when it has fewer findings (stance first) and explains the frame
        about as well (explained points, and :func:`.initialise.score` with the free space), else the fit
        as it was."""
        other, other_status = candidate
        again = self._findings(obs, other)
        fewer = (len(again[0]), len(again[1])) < (len(found[0]), len(found[1]))
        cam = self.rec.camera
        if fewer and other.near_share >= fit.near_share - CHECK_SLACK and \
                score(self.body, other, obs, cam) <= score(self.body, fit, obs, cam) + CHECK_SLACK:
            return other, other_status, again
        return fit, status, found

    def _initialise(self, obs):
        return initialise(self.body, obs, self.rec.camera, self.up, self.opts, self.limits,
                          parts=self.parts).fit

    def _track(self, obs):
        """The frame tracked from the last pose; limbs searched when points are left unexplained, a new
        start when the fit is lost, or when the limb search left points unexplained (a jump between
        poses the fit from the last frame does not follow)."""
        pred = self._prediction()
        _, start, limits = self._held(self.pose if pred is None else pred)
        if pred is None:
            fit = self.fit(self.body, obs, self.rec.camera, start, self.opts, limits)
        else:
            fit = self.fit(self.body, obs, self.rec.camera, start, self.opts, limits, predicted=start)
        status = "tracked"
        if not self._is_lost(fit) and fit.near_share < self._limb_threshold():
            fit, status = self._limbs(obs, fit)
        unexplained = self._is_lost(fit) or fit.near_share < self._limb_threshold()
        if unexplained and not any(cut_edges(obs, sides=True)[2:]):
            again = self._initialise(obs)
            if again.near_share > fit.near_share:
                fit, status = again, "initialised"
        return fit, status

    def _prediction(self):
        """The GMM tracker's predicted pose (its Eq. 6.13 term and start) from the last two frames when
        both were tracked; the ICP tracker starts from the last pose (prediction measured worse there)."""
        if self.opts.tracker != "gmm" or len(self.poses) < 2 or self.poses[-2] is None or self.poses[-1] is None:
            return None
        if not all(f["status"] in FOLLOWED for f in self.frames[-2:]):
            return None
        return extrapolate(self.poses[-2], self.poses[-1], PREDICTION_GAIN)

    def _typical_share(self):
        """The median explained share of the recent frames (None while there are few)."""
        recent = [f["near_share"] for f in self.frames[-RECENT:] if "near_share" in f]
        return float(np.median(recent)) if len(recent) >= RECENT // 2 else None

    def _is_lost(self, fit) -> bool:
        """Below ``lost_share``, or ``LOST_DROP`` below what the recent frames explained."""
        typical = self._typical_share()
        bar = self.opts.lost_share if typical is None else max(self.opts.lost_share, typical - LOST_DROP)
        return fit.near_share < bar

    def _limb_threshold(self) -> float:
        """``limb_share``, or ``LIMB_DROP`` below the recent frames' typical share when that is lower (a
        body the model fits less well, e.g. the template on a clothed person, explains less every frame)."""
        typical = self._typical_share()
        return self.opts.limb_share if typical is None else min(self.opts.limb_share, typical - LIMB_DROP)

    def _limbs(self, obs, fit):
        """A limb lost (observed points left unexplained): the limb search from the fitted pose, kept when
        it explains more (status "limbs searched")."""
        bones, pose, _ = self._held(fit.pose)
        start = place_limbs(self.body, pose, obs, self.rec.camera, self.opts.near_m, self.up, held=bones)
        _, start, limits = self._held(start)
        again = self.fit(self.body, obs, self.rec.camera, start, self.opts, limits)
        if again.near_share > fit.near_share + 0.005:
            return again, "limbs searched"
        return fit, "tracked"

    def _adapt(self, k, obs, fit):
        """The template's body adapted on frame k (size on the first frames, then the surface)."""
        if self.adaptation.wants():
            _, _, limits = self._held(fit.pose)
            self.body, fit = self.adaptation.adapt(k, self.body, fit.pose, obs, self.rec.camera, limits, self.fit)
            return fit
        body = self.adaptation.surface_step(self.body, fit.pose, obs, self.rec.camera)
        if body is not None:
            self.body = body
        return fit


def _fill(poses: list, num_bones: int) -> Poses:
    """Frames without a pose (nobody seen yet) take the first pose found; later gaps keep the last."""
    first = next((p for p in poses if p is not None), None)
    if first is None:
        raise ArticulaInputError("nobody was found in any frame of the recording")
    out, last = [], first
    for p in poses:
        last = p if p is not None else last
        out.append(last)
    return Poses(np.concatenate([p.rotations for p in out]), np.concatenate([p.translations for p in out]),
                 np.concatenate([p.scales for p in out]))


def track_recording(recording, model: Model | None = None, options: DepthTrackOptions = DepthTrackOptions(),
                    limits=None, progress=None) -> DepthTrackResult:
    """Track every frame of ``recording`` (:class:`.source.DepthRecording`) with ``model``, or with the
    built-in template body (:mod:`.template`) adapted to the person when ``model`` is None.  ``limits``:
    the prior terms of every fit (default the generic joint limits,
    :func:`solver.tracking.priors.generic_limits`; ``[]`` for none).  ``progress(fraction, text)`` is called after every frame and may raise :class:`Cancelled`."""
    options.validate()
    template = load_template() if model is None else None
    if template is not None:
        model = template.base
    model.validate()
    t0 = time.perf_counter()
    say = progress or (lambda f, t="": None)
    recording.prepare()
    run = _Sequence(recording, model, options, limits, progress, template)
    n = len(recording)
    t_setup = time.perf_counter() - t0
    t_frames = time.perf_counter()
    with parallel.single_blas_thread():
        for k, obs in recording.observations(options.data_points, person=options.person):
            entry = run.step(k, obs)
            run.frames.append(entry)
            run.poses.append(None if run.pose is None else run.pose)
            say((k + 1) / n, f"frame {k + 1} of {n}: {entry['status']}"
                + (f", {entry['mean_mm']:.1f} mm" if "mean_mm" in entry else ""))
    poses = _fill(run.poses, model.skeleton.num_bones)
    if options.smooth:
        poses = smooth(poses, [f["status"] for f in run.frames])
    seconds = {"setup": t_setup, "frames": time.perf_counter() - t_frames}
    notes = list(recording.notes) + (["the built-in template body was tracked"] if template is not None else [])
    notes += frame_notes(run.frames, options.person)
    return DepthTrackResult(run.body.model, poses, run.frames, notes, options, template is not None, seconds)
