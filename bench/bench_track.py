"""Tracking unregistered 4-view scans of MakeHuman subjects: joint and vertex error, lost frames, time.

Tracking unregistered scans (``solver.track.pipeline.track_sequence``) on sample_scenes recordings:
noisy 4-view scans with outliers (``sample_scenes.unregistered.scan_frame``) of MakeHuman subjects.

Scenarios (``--only`` picks some):

* ``exact``: the subject's exact model, training poses = 30 range-of-motion poses of its rig (what a model
  learned from 30 registered scans carries); cmu_mb female walk and game_engine male random motion;
  no adaptation.  Mean vertex error against the ground truth per frame, lost frames, median scan-to-model
  (the dissertation: 1.92 mm on BUFF), seconds per frame.  Targets: <= 3 mm, no lost frame, <= 1 s.
* ``learned``: a model learned by ``learn_rig`` from 30 registered scans of the same subject; target <= 6 mm.
* ``adapt``: the subject is its model with a planted 1 cm bulge and 2 cm joint offsets; the unchanged model
  tracks with adaptation on: median rest-vertex error and joint error (targets <= 2 mm, <= 1 cm).
* ``speed``: ~150k-point captures (8 x 640x480) and the 13k-vertex model: seconds per frame, peak memory.

Usage: ./run bench track [--frames N] [--only exact,learned,adapt,speed]
"""
import argparse
import os
import resource
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402


def _model(gt):
    from articula.solver.rig.model import Model, Poses, Skeleton
    sk = Skeleton(list(gt["bone_names"]), gt["parents"], gt["heads"], gt["tails"], gt["frames"])
    model = Model(gt["rest_vertices"], gt["faces"], sk, gt["anchor"], gt["twist_weights"], gt["swing_weights"])
    return model, Poses(gt["pose_rotations"], gt["pose_translations"], gt["pose_scales"])


def _recording(rig, shape, motion, frames, seed=0, scan_rig=None):
    """``(posed (N, V, 3), gt, CaptureSource)`` of a smooth motion of a subject, scanned."""
    from articula.sample_scenes import registered, unregistered
    from articula.solver.track.captures import CaptureSource
    options = {"key_every": 6} if motion == "rom" else {}
    posed, faces, gt = registered.posed_sequence(rig=rig, shape=shape, n_poses=frames, motion=motion,
                                                 skin="hybrid", seed=seed, **options)
    pts, tris, cams = [], [], []
    for f in range(frames):
        kw = {} if scan_rig is None else {"rig": scan_rig}
        v, t, _, _, c = unregistered.scan_frame(posed[f], faces, np.random.default_rng([seed, f]), **kw)
        pts.append(v), tris.append(t), cams.append(c)
    return posed, gt, CaptureSource.from_arrays(pts, tris, cams)


def _training_poses(rig, shape):
    from articula.sample_scenes import registered
    return _model(registered.posed_sequence(rig=rig, shape=shape, n_poses=30, motion="rom", skin="hybrid", seed=7)[2])[1]


def _track(model, source, options, training):
    from articula.solver.track import pipeline
    t0, c0 = time.perf_counter(), _common.cpu_seconds()
    res = pipeline.track_sequence(model, source, options, training)
    return res, time.perf_counter() - t0, _common.cpu_seconds() - c0


def _vertex_error(model, poses, posed):
    from articula.solver.rig.skinning import hybrid_skin
    return np.linalg.norm(hybrid_skin(model, poses) - posed, axis=2).mean(axis=1) * 1e3


def _say_run(name, res, seconds, cpu, n, err=None):
    med = [f["median_mm"] for f in res.frames if f["median_mm"] is not None]
    note = (f"{n} frames, {seconds / n:.1f} s/frame wall ({cpu / n:.1f} CPU), lost {res.lost}, skipped "
            f"{res.skipped}, prior {res.prior}, adapted {res.adapted}, median scan-to-model "
            f"{np.median(med):.2f} mm (BUFF 1.92), stages {res.timings}")
    if err is not None:
        _common.report(f"{name}: mean vertex error", float(err.mean()), "mm",
                       f"max frame {err.max():.2f} mm; " + note)
        print("    per frame (mm):", " ".join(f"{e:.1f}" for e in err))
    else:
        _common.report(f"{name}: median scan-to-model", float(np.median(med)), "mm", note)


RECORDINGS = (("cmu_mb", "female", "walk"), ("game_engine", "male", "rom"))


def exact(frames, options, recordings=len(RECORDINGS)):
    for rig, shape, motion in RECORDINGS[:recordings]:
        posed, gt, source = _recording(rig, shape, motion, frames)
        model, _ = _model(gt)
        res, seconds, cpu = _track(model, source, options, _training_poses(rig, shape))
        _say_run(f"exact {rig} {shape} {motion}", res, seconds, cpu, frames, _vertex_error(model, res.poses, posed))


def learned(frames, options):
    from articula.sample_scenes import registered
    from articula.solver.learn.pipeline import learn_rig
    rig, shape = "cmu_mb", "female"
    scans, faces, _ = registered.posed_sequence(rig=rig, shape=shape, n_poses=30, motion="rom", skin="hybrid",
                                                seed=7)
    t0 = time.perf_counter()
    out = learn_rig(scans, faces)
    _common.report("learned: learn_rig from 30 registered scans", time.perf_counter() - t0, "s")
    posed, gt, source = _recording(rig, shape, "walk", frames)
    res, seconds, cpu = _track(out.model, source, options, out.poses)
    _say_run(f"learned {rig} {shape} walk", res, seconds, cpu, frames, _vertex_error(out.model, res.poses, posed))


def planted_subject(model, bulge=0.01, offset=0.02, seed=3):
    """The issue's wrong-model case: ``model`` with a 1 cm bulge on the belly (8 cm radius, smooth) and
    every left joint centre moved 2 cm in a random direction, its right twin mirrored (the trunk's
    joints in the mid-plane).  Returns ``(subject Model, bulge profile (V,))``."""
    from articula.solver.track.adapt import adapted_model
    from articula.solver.track.visibility import vertex_normals
    x0, sk = model.rest_vertices, model.skeleton
    nrm = vertex_normals(x0, model.faces)
    c = x0[np.argmin(np.linalg.norm(x0 - np.array([0.0, -0.2, 1.05]), axis=1))]
    prof = np.clip(1 - (np.linalg.norm(x0 - c, axis=1) / 0.08) ** 2, 0, None) ** 2 * (nrm[:, 1] < -0.3)
    heads, names, rng = sk.heads.copy(), sk.names, np.random.default_rng(seed)
    for b in range(1, sk.num_bones):
        o = rng.normal(size=3)
        if names[b].endswith(".L"):
            heads[b] += offset * o / np.linalg.norm(o)
            heads[names.index(names[b][:-1] + "R")] += offset * o / np.linalg.norm(o) * [-1, 1, 1]
        elif not names[b].endswith(".R"):
            o[0] = 0.0
            heads[b] += offset * o / np.linalg.norm(o)
    return adapted_model(model, x0 + bulge * prof[:, None] * nrm, heads), prof


def adapt(frames, options):
    """The cmu_mb female model with a planted bulge and joint offsets stands for the subject; the
    unchanged model tracks the subject's walk with adaptation on."""
    import dataclasses
    from articula.sample_scenes import registered, unregistered
    from articula.solver.rig.skinning import hybrid_skin
    from articula.solver.track.captures import CaptureSource
    _, faces, gt = registered.posed_sequence(rig="cmu_mb", shape="female", n_poses=frames, motion="walk",
                                             skin="hybrid", seed=0)
    model, truth = _model(gt)
    subject, prof = planted_subject(model)
    posed = hybrid_skin(subject, truth)
    caps = [unregistered.scan_frame(posed[f], faces, np.random.default_rng([0, f])) for f in range(frames)]
    source = CaptureSource.from_arrays([c[0] for c in caps], [c[1] for c in caps], [c[4] for c in caps])
    res, seconds, cpu = _track(model, source, dataclasses.replace(options, adapt="on"),
                               _training_poses("cmu_mb", "female"))
    x = subject.rest_vertices
    for label, m in (("before", model), ("after", res.model)):
        d = np.linalg.norm(m.rest_vertices - x, axis=1) * 1e3
        j = np.linalg.norm(m.skeleton.heads[1:] - subject.skeleton.heads[1:], axis=1) * 1e3
        _common.report(f"adapt {label}: rest vertices to the planted subject's, median", float(np.median(d)), "mm",
                       f"bulge median {np.median(d[prof > 0.5]):.2f} mm; joints mean {j.mean():.1f} mm, "
                       f"max {j.max():.1f} mm (targets: surface <= 2 mm median, joints <= 10 mm)")
    _say_run("adapt cmu_mb female, planted 1 cm bulge and 2 cm joints", res, seconds, cpu, frames,
             _vertex_error(res.model, res.poses, posed))


def speed(frames, options):
    import dataclasses
    from articula.sample_scenes.unregistered import ScanRig
    rig = ScanRig(n_cameras=8, resolution=(640, 480), resolution_scale=(1.0, 1.0))
    posed, gt, source = _recording("cmu_mb", "female", "walk", frames, scan_rig=rig)
    sizes = [len(source._reader(i)[0]) for i in range(frames)]
    model, _ = _model(gt)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    res, seconds, cpu = _track(model, source, dataclasses.replace(options, adapt="on"),
                               _training_poses("cmu_mb", "female"))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    _common.report("speed: seconds per frame, 13,380-vertex model, adaptation on", seconds / frames, "s",
                   f"captures {min(sizes)}-{max(sizes)} points (thinned to {options.max_points}); peak RSS "
                   f"{peak / 1024:.0f} MB (+{(peak - base) / 1024:.0f} MB); target 1 s; stages {res.timings}")


SCENARIOS = {"exact": exact, "learned": learned, "adapt": adapt, "speed": speed}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench track")
    p.add_argument("--frames", type=int, default=12, help="frames per recording (default 12)")
    p.add_argument("--only", default=",".join(SCENARIOS), help="comma-separated scenarios")
    args = p.parse_args(argv)
    from articula.solver.track.options import TrackOptions
    options = TrackOptions(adapt="off")
    for name in args.only.split(","):
        print(f"# ./run bench track --frames {args.frames} --only {name}")
        SCENARIOS[name.strip()](args.frames, options)
    return 0


if __name__ == "__main__":
    sys.exit(main())
