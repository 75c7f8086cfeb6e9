"""Tracking unregistered 4-view captures: body, extremity and joint errors vs truth, lost frames, time.

Every case is outside the sample defaults (cmu_mb female walk): other rigs, shapes, macro seeds and motions,
including ``sample_scenes.reach`` (arms raised above the head, trunk bending and twisting, turning).
Errors are measured against the ground truth (``_track_metrics``), never the tracker's residual: per run
the mean over frames and vertices, then body only, extremities (hands, fingers, feet, toes, head) and the
14 major joints separately, lost frames and seconds per frame, each line with its target and ratio.
Captures (``_track_cases``): "clean" (no noise, no outliers), "1mm" (1 mm depth noise) at 4 x 640x480,
thinned by the tracker to 20,000 points; "kinect" the samples' default Kinect-like scans.  First frame
automatic (``--start truth``: the true first pose instead, for the exact models of clean, noisy, worlds
and speed); tracker options are ``TrackOptions()``'s defaults except ``adapt`` in the adaptation scenario.

Scenarios (``--only`` picks some; default frames in brackets, ``--frames`` overrides):

* ``clean`` [12]: exact model, noise-free captures, game_engine male (seed 21), reach.  Target <= 0.5 mm.
* ``noisy`` [12]: exact model, 1 mm captures: mixamo female,heavy (seed 4) walk and game_engine male (seed
  21) reach; then the reach on Kinect-like captures (secondary).  Target <= 3 mm, 0 lost frames.
* ``worlds`` [12]: the game_engine reach on 1 mm captures with the world Z-up, Y-up and tilted 30 degrees
  (captures and truth rotated, errors in the rotated world).  Target: the same numbers (<= 3 mm each).
* ``learned`` [12]: ``learn_rig`` from 30 registered range-of-motion scans of mixamo male,old (seed 12),
  tracking a walk of that subject (1 mm), first frame automatic.  Target <= 10 mm.
* ``adapt`` [12]: another body's model tracking the subject with ``adapt="on"`` and ``"off"``: game_engine
  male,thin (seed 9) tracking game_engine female,heavy (seed 8), and the built-in template body
  (``solver.track_depth.template``: MakeHuman default macros, cmu_mb without fingers) tracking cmu_mb
  male,heavy (seed 5); walks on 1 mm captures.  Mean distance from the subject's true posed surface to
  the adapted, posed model: target <= 4 mm and off/on >= 2; then the subject's own exact model (game_engine
  female,heavy) with and without adaptation: target on/off 0.95-1.05 (adaptation changes nothing); for
  each, what the default ``adapt="auto"`` decides from the run without adaptation (another body's model
  adapted, the subject's own kept).
* ``speed`` [40]: exact model, game_engine female (seed 31) walk on 1 mm captures (thinned to 20,000
  points): seconds per frame tracking (target 1 s) and wall including start-up (target 2 s).

Usage: ./run bench track [--frames N] [--only clean,noisy,worlds,learned,adapt,speed] [--start auto|truth]
"""
import argparse
import dataclasses
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import _track_cases as cases  # noqa: E402
from _track_cases import Subject  # noqa: E402

REACHER = Subject("game_engine", "male", 21)
WALKER = Subject("mixamo", "female,heavy", 4)
LEARNED = Subject("mixamo", "male,old", 12)
ADAPT_SUBJECT, ADAPT_OTHER = Subject("game_engine", "female,heavy", 8), Subject("game_engine", "male,thin", 9)
TEMPLATE_SUBJECT = Subject("cmu_mb", "male,heavy", 5)
SPEEDY = Subject("game_engine", "female", 31)


def _exact(label, rec, options, start, target):
    model = rec.model
    run = cases.track(model, rec, options, cases.training_poses(model.skeleton), start)
    return cases.report_run(label, run, rec, target)


def clean(frames, options, start):
    rec = cases.record(REACHER, "reach", frames, "clean")
    _exact(f"clean: exact model, {rec.label}", rec, options, start, 0.5)


def noisy(frames, options, start):
    for subject, motion, capture in ((WALKER, "walk", "1mm"), (REACHER, "reach", "1mm"),
                                     (REACHER, "reach", "kinect")):
        rec = cases.record(subject, motion, frames, capture)
        _exact(f"noisy: exact model, {rec.label}", rec, options, start, 3.0)


def worlds(frames, options, start):
    means = {}
    for world in ("zup", "yup", "tilt30"):
        rec = cases.record(REACHER, "reach", frames, "1mm", world)
        means[world] = _exact(f"worlds: exact model, {rec.label}", rec, options, start, 3.0)["all"]
    spread = max(means.values()) - min(means.values())
    _common.report("worlds: largest minus smallest mean vertex error over the worlds", spread, "mm",
                   "target: the same numbers; " + ", ".join(f"{k} {v:.2f} mm" for k, v in means.items()))


def learned(frames, options, start):
    from articula.solver.learn.pipeline import learn_rig
    from articula.solver.rig.skinning import hybrid_skin
    body = LEARNED.build()
    scans = hybrid_skin(body.hybrid_model(), cases.training_poses(body.skeleton))
    t0 = time.perf_counter()
    out = learn_rig(scans, body.triangles)
    _common.report(f"learned: learn_rig from 30 registered scans of {LEARNED.label}", time.perf_counter() - t0,
                   "s", f"{out.model.skeleton.num_bones} parts")
    rec = cases.record(LEARNED, "walk", frames, "1mm", seed=3)
    run = cases.track(out.model, rec, options, out.poses)         # always automatic: no true pose of its bones
    cases.report_run(f"learned: learn_rig model, {rec.label} (a new motion)", run, rec, 10.0)


def _adapted_pair(label, model, training, rec, options, own=False):
    """Track ``rec`` with ``model`` adapting and not; another body's model must gain >= 2x, the subject's
    own (``own``) must stay as it is (with / without within 5 %)."""
    runs = {}
    for adapt in ("on", "off"):
        run = cases.track(model, rec, dataclasses.replace(options, adapt=adapt), training)
        runs[adapt] = cases.report_run(f"adapt: {label}, adapt {adapt}", run, rec, 3.0 if own else 4.0,
                                       surface=True)["all"]
    _auto_decision(label, model, rec, run.result, options, own)
    if own:
        _common.report(f"adapt: {label}, with / without adaptation", runs["on"] / runs["off"], "",
                       f"target 0.95-1.05: changes nothing; {runs['on']:.2f} mm / {runs['off']:.2f} mm")
        return
    _common.report(f"adapt: {label}, without / with adaptation", runs["off"] / runs["on"], "",
                   f"target >= 2; {runs['off']:.2f} mm / {runs['on']:.2f} mm")


def _auto_decision(label, model, rec, result, options, own):
    """What adapt "auto" decides for ``model`` on ``rec`` from the poses of the run without adaptation."""
    from articula.solver.track.adaptation import SHAPE_OFF, model_offset
    from articula.solver.track.options import ADAPT_MIN_FRAMES
    from articula.solver.track.recording import Recording
    from articula.solver.tracking.body import Body
    recording = Recording(rec.source, options)
    for i in range(len(recording)):
        recording.capture(i)
    poses = {i: result.poses.take([i]) for i in range(len(recording))}
    offset = model_offset(Body(model), recording, poses, options.adapt_every)
    adapts = offset > SHAPE_OFF
    _common.report(f"adapt: {label}, model off the captures (auto's measure)", offset * 1e3, "mm",
                   f"auto adapts above {SHAPE_OFF * 1e3:g} mm on >= {ADAPT_MIN_FRAMES} frames: "
                   f"{'adapts' if adapts else 'keeps the model'}; target: "
                   f"{'keeps the model' if own else 'adapts'}: {'met' if adapts != own else 'MISSED'}")


def adapt(frames, options, start):
    from articula.solver.track_depth.template import load_template
    subject = cases.record(ADAPT_SUBJECT, "walk", frames, "1mm", seed=5)
    other = ADAPT_OTHER.build().hybrid_model()
    _adapted_pair(f"{ADAPT_OTHER.label} model, {subject.label}", other, cases.training_poses(other.skeleton),
                  subject, options)
    rec = cases.record(TEMPLATE_SUBJECT, "walk", frames, "1mm", seed=6)
    _adapted_pair(f"template body, {rec.label}", load_template().base, None, rec, options)
    _adapted_pair(f"own model, {subject.label}", subject.model, cases.training_poses(subject.model.skeleton),
                  subject, options, own=True)


def speed(frames, options, start):
    rec = cases.record(SPEEDY, "walk", frames, "1mm", seed=2)
    _exact(f"speed: exact model, {rec.label}", rec, options, start, 3.0)


SCENARIOS = {"clean": (clean, 12), "noisy": (noisy, 12), "worlds": (worlds, 12), "learned": (learned, 12),
             "adapt": (adapt, 12), "speed": (speed, 40)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench track")
    p.add_argument("--frames", type=int, default=None, help="frames per recording (default: per scenario)")
    p.add_argument("--only", default=",".join(SCENARIOS), help="comma-separated scenarios")
    p.add_argument("--start", choices=("auto", "truth"), default="auto",
                   help="first frame: the tracker's automatic start or the true pose (exact models only)")
    args = p.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        p.error(f"unknown scenario(s) {', '.join(unknown)} (choose from {', '.join(SCENARIOS)})")
    if args.frames is not None and args.frames < 2:
        p.error("--frames: at least 2")
    from articula.solver.track.options import TrackOptions
    options = TrackOptions()
    for name in names:
        fn, default = SCENARIOS[name]
        frames = args.frames or default
        print(f"# ./run bench track --frames {frames} --only {name} --start {args.start}", flush=True)
        fn(frames, options, args.start)
    return 0


if __name__ == "__main__":
    sys.exit(main())
