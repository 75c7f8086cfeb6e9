"""Pass 1 of the scan tracker: every frame in order from its constant-velocity prediction.

Frame n starts at the pose predicted from the last two good frames (``q_n = q_{n-1} (q_{n-2}^-1
q_{n-1})`` per bone, the root moving on as it moved) and is held along the directions its data barely
constrain (:func:`solver.tracking.priors.weak_directions`; in the converging stage as firmly as the
captures are noisy: :func:`capture_noise`) to a prediction carrying on half that velocity
(``HOLD_CARRY``): held to the full prediction, a direction no data see (a finger with no capture
points) keeps any velocity it once had for ever; held to this one, its velocity halves every frame.  The
target's rotations are also turned a fifth of the way back to rest (``HOLD_RELAX``), so where the data
say nothing the pose forgets where the run started: a chunk of a recording started elsewhere comes to
the same poses within a few frames (the farm, docs/track.md "7 Dec").  A
frame whose median capture-to-model distance jumps (above ``lost_factor`` x the running median and
``lost_mm``) is searched again from the start hypotheses and the last good pose (:func:`.first_frame.find_pose`) and
listed as lost when that does not bring it back; the next frame then starts from the last good pose.
A frame the truth-free checks call lost is fitted again from the last good pose with coverage and keeps
the new fit only when it explains the capture clearly better: a limb on a wrong surface leaves capture
regions unexplained and scores many times worse, while a few per cent is the noise of fingers and folds
(docs/track.md "Design").
"""
from __future__ import annotations

import time

import numpy as np

from ..geometry.rotations import quat_to_rotvec, rotvec_to_quat
from ..rig.model import Poses
from ..tracking.frame import SEARCH, SEARCH_HOLD, TRACKING, FrameSettings, capture_noise, fit_frame
from ..tracking.checks import check_frame
from ..tracking.lm import State
from ..tracking.motion import extrapolate
from .first_frame import capture_score, find_pose
from .trail import RUNNING, Resume, Trail

BETTER = 0.8            # a search replaces a flagged frame's fit when its capture score is below this share
HOLD_CARRY = 0.5        # share of the last velocity the weak directions' hold target carries on
HOLD_RELAX = 0.2        # share of the way back to rest the hold target's rotations turn each frame


def predict(history, carry: float = 1.0) -> Poses:
    """The next pose from the last one or two good poses (one frame each), moving on by ``carry`` times
    the last frame's motion (1: constant velocity; 0: the last pose)."""
    return history[-1] if len(history) < 2 else extrapolate(history[-2], history[-1], carry)


def relaxed(pose: Poses, share: float = None) -> Poses:
    """``pose`` with every bone's rotation turned ``share`` (default ``HOLD_RELAX``) of the way back to
    rest along the shorter arc (the root's translation kept)."""
    share = HOLD_RELAX if share is None else share
    if not share:
        return pose
    rot = rotvec_to_quat((1.0 - share) * quat_to_rotvec(pose.rotations))
    return Poses(rot, pose.translations, pose.scales)


def median_mm(state, points) -> float:
    """Median distance (mm) of ``points`` to the state's posed surface (one-ring closest points)."""
    _, _, foot, _ = state.surface.closest(points)
    return float(np.median(np.linalg.norm(points - foot, axis=1)) * 1e3)


def follow(body, rec, first: int, pose: Poses, options, settings: FrameSettings, priors=(), say=None,
           cancel=None, checked=None, resume: Resume = None, trail: Trail = None) -> dict:
    """``{tracked frame: pose}`` of pass 1 from tracked frame ``first`` at ``pose``; fills the report
    entries (median, lost, re-initialised, reason, seconds).  ``say(i, median mm)`` reports progress;
    ``checked``: the model prepared for the truth-free checks: a frame they call lost is searched again
    near where it is (from the last good pose through the searched frame's finer stages, with coverage;
    a jump gets the full search of the first frame), and keeps its fit unless the search explains the
    capture clearly better (:func:`explains_better`) and passes them (when it does not, the frames after
    it that fail them are not searched until one passes: a subject that really touches itself fails them
    throughout).  ``resume``: the state another run left after this run's first frame (``pose`` is its
    pose): pass 1 goes on as that run did; ``trail``: records the state after every frame.  A frame's fit
    depends on that state and its capture only (its sample is seeded by its input frame number), so a
    resumed run repeats the other's frames."""
    history, out = [pose], {first: pose}
    medians = [rec.entries[first]["median_mm"]] if rec.entries[first].get("median_mm") is not None else []
    searched_in_vain = False          # the last frame the checks failed was searched again without a better fit
    if resume is not None:
        history, medians, searched_in_vain = resume.history, list(resume.medians), resume.in_vain
        if resume.held is not None:
            body.hold(resume.held)
    if trail is not None:
        trail.record(first, history, medians, searched_in_vain, body.held_pose())
    for i in range(first + 1, len(rec)):
        t0 = time.perf_counter()
        capture = rec.capture(i)
        rec.prefetch(i + 1)
        if rec.too_few(i):
            continue
        guess = predict(history)
        fit = fit_frame(body, capture.points, capture.normals, guess, target=relaxed(predict(history, HOLD_CARRY)),
                        settings=settings, stages=TRACKING, cancel=cancel, seed=rec.range[i],
                        noise=capture_noise(medians[-RUNNING:]))
        med = median_mm(fit.state, _sample(capture.points))
        limit = max(options.lost_factor * float(np.median(medians[-RUNNING:])) if medians else 0.0,
                    options.lost_mm)
        fit_pose = fit.pose
        jump = med > limit
        flagged = not jump and _lost(body, capture, fit.pose, fit.state.posed, checked)
        if not flagged:
            searched_in_vain = False
        if jump or (flagged and not searched_in_vain):
            if jump:
                searched = _again(body, capture, history[-1], options, settings, priors, cancel, checked)
            else:
                searched = _nearby(body, capture, history[-1], settings, priors, cancel)
            again, again_med = searched.pose, median_mm(searched, _sample(capture.points))
            rec.entries[i]["reinitialised"] = True
            if jump and again_med > limit:
                rec.entries[i].update(lost=True, median_mm=again_med, reason=f"median {again_med:.1f} mm "
                                      f"after re-initialisation (limit {limit:.1f} mm)")
                rec.entries[i]["seconds"] = round(time.perf_counter() - t0, 3)
                history = history[-1:]
                if trail is not None:
                    trail.record(i, history, medians, searched_in_vain, body.held_pose(), fitted=False)
                continue
            if jump or (explains_better(body, capture, searched, fit.state)
                        and not _lost(body, capture, again, searched.posed, checked)):
                fit_pose, med = again, again_med
            else:                                     # the search explains the capture no better or fails the
                searched_in_vain = True               # checks too: keep the fit, and do not search the next
                                                      # frames while they fail alike
        rec.entries[i].update(median_mm=med, seconds=round(time.perf_counter() - t0, 3))
        medians.append(med)
        history = (history + [fit_pose])[-2:]
        out[i] = fit_pose
        if trail is not None:
            trail.record(i, history, medians, searched_in_vain, body.held_pose())
        if say is not None:
            say(i, med)
    return out


def explains_better(body, capture, searched, fitted) -> bool:
    """True when the ``searched`` state explains ``capture`` clearly better than the ``fitted`` one: its
    capture score (:func:`.first_frame.capture_score`) is below ``BETTER`` times the fit's."""
    return capture_score(body, capture, searched) < BETTER * capture_score(body, capture, fitted)


def _lost(body, capture, pose, posed, checked) -> bool:
    return checked is not None and check_frame(body.model, pose, posed, capture, checked).verdict == "lost"


def _nearby(body, capture, last, settings, priors, cancel) -> State:
    """A frame the checks flag searched near where it is: the state of the fit from the last good pose
    through the searched frame's finer stages (coverage at 8 cm reach pulls a limb off a surface another
    part explains)."""
    return fit_frame(body, capture.points, capture.normals, last, priors=priors, stages=SEARCH[1:],
                     settings=settings, cancel=cancel, weak_ratio=SEARCH_HOLD).state


def _again(body, capture, last, options, settings, priors, cancel, checked=None) -> State:
    """A lost frame searched again: the state of the best fit."""
    pose, _, _ = find_pose(body, capture, priors, extra=[last], count=options.hypotheses, settings=settings,
                           cancel=cancel, checked=checked)
    return State(body, pose)


def _sample(points, count: int = 4000):
    if len(points) <= count:
        return points
    return points[np.random.default_rng(0).choice(len(points), count, replace=False)]
