"""Rig learning vs exact ground truth and Dem Bones: training/held-out error, joints, time, memory.

Evaluation of rig learning (issues 4 and 19) against exact ground truth and the peer tool Dem Bones:
training error, held-out error, joint-centre error, time and memory of ``solver.learn.pipeline.learn_rig``.
(``bench_learn_speed.py`` times the learner's stages; this one evaluates the result.)  Helpers:
``_learn_runs.py``; section 0: ``_learn_bodies.py``.

Sections (every number with its unit; the output is also written to ``bench/results/``):

0. Issue 19 (``--order issue19``; ``_learn_bodies.py`` has the definitions): MakeHuman ``cmu_mb`` subjects
   of three shapes (range-of-motion poses + walk frames), the skinning_gt wolf and the fox sequence; per
   case ``learn_rig`` with its default options, then Dem Bones with as many bones as ours chose, in the same
   run.  One row per case: RMSE ratio (ours / Dem Bones), wall-time ratio (our whole learn_rig call, report
   included, / Dem Bones' ``compute()``), worst joint distance outside the learned rest mesh (fraction of
   the bounding-box diagonal, 0 inside), mirror pairs and, for the quadrupeds, whether the front and hind
   leg pairs are found, parts without vertices, and for MakeHuman how many of the 14 major joints have a
   learned joint within 2 cm (the misses named with their distance); then each target met or missed.

1. MakeHuman sequences (``sample_scenes.registered.posed_sequence``; 13,380 vertices; rigs ``cmu_mb`` and
   ``game_engine``; shapes ``female,heavy`` and ``male,thin``; generating skins ``lbs`` and ``hybrid``;
   30 random range-of-motion training poses + 10 held-out poses from another seed):
   * training error: every training-scan vertex to the surface of the learned model posed with its learned
     pose (mm: mean, std, median, MAD, IQR, max — spec §4.1 / §6.1, ``_learn_metrics``);
   * held-out error: the learned model FIXED, one pose per held-out scan fitted by ``solver.fit.pose_fit``
     (Levenberg–Marquardt from a per-part Procrustes start), the same distance;
   * joint-centre error: learned joint centres matched to the generating rig's joints (Hungarian
     assignment, ``_learn_metrics.match_joints``), both posed in every training scan (the learned rest pose
     is one of the scans), mean distance over the scans per matched pair, mm;
   * wall and CPU time, and peak resident memory of the learning process (a fresh child process per
     run, ``VmHWM``; its baseline after the imports is printed too).
   A reference row needs no learner: ``pose_fit`` with the generating rig's own hybrid model on the held-out
   scans (0 mm for hybrid-skinned data: checks the fitter and the metric end to end).
2. ``../shared/data/skinning_gt`` cylinder and wolf (libigl .tgf skeleton, .DMAT weights, .Tmat transforms,
   posed OBJ meshes; ``_libigl``): the exact rig's own reproduction error (reader check), Dem Bones
   with as many bones as the rig, and ``learn_rig`` with as many parts: reconstruction error and joint-centre
   error against the rig's joints, in the files' units and relative to the bounding-box diagonal.
3. Dem Bones (``py-dem-bones`` 0.13.1 from PyPI, in its own virtual environment
   ``$ARTICULA_HOME/venv-dembones``, run in a subprocess by ``bench/dembones_runner.py``; never imported by
   Articula) with its default parameters, on its own example ``Bone_Anim`` (400 frames x 754 vertices, rest
   ``Bone_Geom_rest.obj``, whose vertex order equals the frames') at 5, 10 and 20 bones and on the first
   MakeHuman training sequence at our part count, next to ``learn_rig`` with parts = 5 / 10 / 20 / ours.
   On Bone_Anim ours runs three times per count: with the defaults (α = 100, joint prior ρ = 0.01) and
   with α = 1 and no joint prior (both with the default key scans: learned from 40 of the 400 frames, the
   other frames' poses fitted with the learned model), and with α = 1, no prior, learned from all 400
   frames (``key_scans=None``).  Every "ours" row gives wall
   time, process CPU time and the solver's thread count (its default: one per core, as Dem Bones' OpenMP).
   RMSE measures the data term alone, which is all Dem Bones minimises; our objective adds α × the Laplacian (local shape) term,
   and the prior holds joints near their initial estimates, so α = 1 without the prior is the setting that
   optimises what the RMSE measures (the shape term still regularises).
   Dem Bones runs with its OpenMP threads (all cores) and OMP_WAIT_POLICY=PASSIVE (spinning threads made it
   ~10x slower on the shared machine).
   RMSE exactly as Dem Bones defines it (``DemBones::rmse``): sqrt(Σ_frames Σ_vertices ‖x̂ − x‖² / (N·V)),
   checked against the value Dem Bones itself reports; published: 0.0268 / 0.0156 / 0.0099.
   Times: Dem Bones' is that of its ``compute()`` (its ``rmse()`` and the data set-up run outside it); ours is
   printed as the child's whole ``learn_rig`` wall time split into learning and the error report (the exact
   vertex-to-surface statistics over every scan, ``report["timings_s"]["report"]``), and the time ratio
   compares the learning part with ``compute()``.
   Note: Dem Bones' bones are free rigid transforms per frame (6 DoF each, no skeleton), ours are parts of
   one kinematic tree (3 DoF per joint), so at equal counts Dem Bones has more freedom.

4. (only with ``--order tube``) the synthetic tube body of the solver tests (``sample_scenes/tube_scans.py``,
   509 vertices, 8 parts, hybrid-skin ground truth): 8 training scans, 4 held-out poses from another seed;
   training and held-out error, and joint centres vs the true joints, as in section 1.  Small and quick:
   a check of the whole evaluation path with known truth.

If ``solver.learn.pipeline.learn_rig`` cannot be imported or fails, every "ours" row prints FAILED with the reason
and the benchmark exits with status 1 after printing everything else; no number is ever invented.

Usage: ./run bench learn [--quick] [--no-dembones] [--order SECTIONS] [--cases CASES] [--out FILE]
       ./run bench learn --order issue19          (section 0 alone: bench/results/learn-issue19.txt)
       ~/.cache/articula/venv-bpy52/bin/python bench/bench_learn.py [--quick]
--quick: section 0 on mh/female-heavy and the fox; one MakeHuman case per rig (cmu_mb female,heavy hybrid;
game_engine male,thin lbs), Bone_Anim at 5 and 10 bones, the cylinder only.  Results: bench/results/learn.txt
(learn-quick.txt with --quick; learn-issue19[-quick].txt when section 0 runs alone).
"""
import argparse
import datetime
import os
import resource
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import numpy as np  # noqa: E402

import _learn_bodies as i19  # noqa: E402
import _learn_runs as runs  # noqa: E402  (also makes ``import articula`` work)
from _learn_runs import (HERE, REPO, SHARED, DEMBONES_PIN, Tee, line, stats_text, machine,  # noqa: E402
                         learner_status, learn_detail, learn_or_fail, versus, wall_split, dembones_python,
                         run_dembones, rmse_and_seconds, bone_anim, skinning_gt, part_joints, surface_stats,
                         held_out, posed_joints, joint_errors)

DEMBONES_PUBLISHED = {5: 0.0268, 10: 0.0156, 20: 0.0099}
TRAIN_POSES, TEST_POSES = 30, 10
# learn_rig's default α, and a small α (RMSE measures the data term only); True: from every scan, not key scans
BONE_ANIM_RUNS = ((100.0, False), (1.0, False), (1.0, True))


# ------------------------------------------------------------------------------------------ sections

def makehuman_cases(quick):
    if quick:
        return [("cmu_mb", "female,heavy", "hybrid"), ("game_engine", "male,thin", "lbs")]
    return [(r, s, k) for r in ("cmu_mb", "game_engine") for s in ("female,heavy", "male,thin")
            for k in ("lbs", "hybrid")]


def section_makehuman(args, tmp, have_learner, why, failures, ours):
    from articula.sample_scenes.registered import posed_sequence
    from articula.sample_scenes.subjects import make_subject
    line("== 1. MakeHuman sequences: learned model vs the generating rig")
    first = None
    for rig, shape, skin in makehuman_cases(args.quick)[args.mh_skip:][:args.mh_cases or None]:
        t0 = time.perf_counter()
        train, faces, gt = posed_sequence(rig, shape, TRAIN_POSES, "rom", skin, seed=0)
        test, _, _ = posed_sequence(rig, shape, TEST_POSES, "rom", skin, seed=1)
        gen = time.perf_counter() - t0
        if first is None:
            first = (train, faces, f"{rig} / {shape} / {skin}")
        B = len(gt["bone_names"])
        line(f"-- {rig} / {shape} / {skin} skin: {TRAIN_POSES} training + {TEST_POSES} held-out poses, "
             f"{train.shape[1]} vertices, generating rig {B} bones  (data {gen:.1f} s)")
        if not args.no_reference:
            exact = make_subject(rig, shape).hybrid_model()
            stats, fit, sec = held_out(exact, test)
            what = "exact skin: expect 0" if skin == "hybrid" else "hybrid skin of the LBS rig, exact joints"
            line(f"   reference: generating rig's hybrid model, held-out poses by pose_fit ({what}): "
                 f"{stats_text(stats)}; {sec / TEST_POSES:.2f} s/frame, {fit.iterations.mean():.1f} LM iterations, "
                 f"{int(fit.converged.sum())}/{TEST_POSES} converged")
        got = learn_or_fail((have_learner, why, failures), f"makehuman {rig}/{shape}/{skin}", "   ours",
                            train, faces, args.parts, tmp)
        if got is None:
            continue
        model, poses, meas = got
        k = model.skeleton.num_bones
        tr, tr_rmse = surface_stats(train, model, poses)
        ours.setdefault("makehuman", (k, tr_rmse, meas))
        ho, hfit, hsec = held_out(model, test)
        ref_heads = gt["posed_heads"][:, 1:]
        je = joint_errors(posed_joints(model, poses), ref_heads) * 1000
        how = "chosen by learn_rig" if not args.parts else "given with --parts"
        line(f"   ours: {k} parts ({how}), {wall_split(meas)}, {learn_detail(meas, len(train))}, "
             f"peak RSS {meas['rss_peak_kb'] / 1024:.0f} MB (baseline after imports {meas['rss_base_kb'] / 1024:.0f} MB)")
        line(f"   ours training error (scan vertex -> learned surface): {stats_text(tr)}")
        line(f"   ours held-out error ({TEST_POSES} poses fitted by pose_fit, model fixed): {stats_text(ho)}; "
             f"{hsec / TEST_POSES:.2f} s/frame, {int(hfit.converged.sum())}/{TEST_POSES} converged")
        line(f"   ours joint centres vs generating rig, posed in every training scan ({len(je)} learned joints "
             f"matched among {ref_heads.shape[1]}; distance averaged over the scans): "
             f"mean {je.mean():.1f}  median {np.median(je):.1f}  max {je.max():.1f} mm")
    return first


def section_skinning_gt(args, tmp, have_learner, why, failures, db_py):
    line("== 2. skinning_gt (exact rigs, libigl formats; lengths in the files' units)")
    for name in args.gt or (("cylinder",) if args.quick else ("cylinder", "wolf")):
        d = os.path.join(SHARED, "skinning_gt", f"{name}-all")
        if not os.path.isdir(d):
            line(f"-- {name}: SKIPPED ({d} not present)")
            continue
        g = skinning_gt(name)
        N, V = g["scans"].shape[:2]
        B = len(g["bones"])
        diag = float(np.linalg.norm(g["rest"].max(0) - g["rest"].min(0)))
        ref_joints = part_joints(g)
        err = np.abs(g["exact"] - g["scans"]).max()
        islands = (f" (largest connected part: {g['dropped']} vertices of separate islands dropped, as "
                   f"learn_rig needs one connected mesh; Dem Bones gets the same)" if g["dropped"] else "")
        line(f"-- {name}: {N} posed meshes x {V} vertices{islands}, {B} bones, {len(g['joints'])} joints, "
             f"rest bounding-box diagonal {diag:.3f}")
        line(f"   exact rig (.DMAT weights, .Tmat transforms) reproduces the meshes to {err:.2e} "
             f"({err / diag:.1e} of the diagonal; the files are rounded)")
        db = None
        if db_py is not None:
            try:
                out = run_dembones(db_py, g["rest"], g["scans"], g["faces"], B, tmp)
                db = rmse_and_seconds(out)
                line(f"   Dem Bones ({int(out['bones'])} bones, given the rig's rest mesh): RMSE {float(out['rmse']):.4f} "
                     f"({float(out['rmse']) / diag:.2e} of diag), {float(out['seconds']):.2f} s")
            except RuntimeError as e:
                line(f"   Dem Bones: FAILED - {e}")
        got = learn_or_fail((have_learner, why, failures), f"skinning_gt {name}", "   ours", g["scans"], g["faces"],
                            B, tmp)
        if got is None:
            continue
        model, poses, meas = got
        stats, rmse = surface_stats(g["scans"], model, poses)
        je = joint_errors(posed_joints(model, poses), ref_joints)
        mean, worst = stats["mean"] / 1000, stats["max"] / 1000                  # back to file units
        line(f"   ours ({model.skeleton.num_bones} parts, {wall_split(meas)}): scan -> learned surface mean "
             f"{mean:.4f} max {worst:.4f} ({mean / diag:.2e} of diag); RMSE (Dem Bones' definition) {rmse:.4f}"
             f"{versus(db, rmse, meas)}")
        line(f"   ours joint centres vs the rig's joints, posed in every scan ({len(je)} matched among "
             f"{ref_joints.shape[1]}; distance averaged over the scans): mean "
             f"{je.mean():.4f} ({je.mean() / diag:.2e} of diag), max {je.max():.4f}")


def section_dembones(args, tmp, have_learner, why, failures, db_py, first_mh, ours):
    import _learn_metrics as metrics
    line("== 3. Dem Bones (py-dem-bones 0.13.1, default parameters, own venv) vs learn_rig")
    line("   RMSE = sqrt(sum over frames and vertices of |reconstruction - target|^2 / (frames * vertices)), "
         "as DemBones::rmse()")
    if not os.path.isdir(os.path.join(SHARED, "dem_bones")):
        line("   SKIPPED: ../shared/data/dem_bones not present")
        return
    rest, frames, polys, tris = bone_anim()
    diag = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    order = float(np.abs(frames[0] - rest).max())
    line(f"-- Bone_Anim: {frames.shape[0]} frames x {frames.shape[1]} vertices; rest bounding-box diagonal "
         f"{diag:.3f} (published 4.418); frame 0 equals the rest mesh vertex by vertex to {order:.1e} (same order)")
    counts = [c for c in (args.bone_counts or ((5, 10) if args.quick else (5, 10, 20))) if c > 0]
    for bones in counts:
        pub = DEMBONES_PUBLISHED.get(bones, "-")
        db = None
        if db_py is None:
            line(f"   {bones:2d} bones  Dem Bones: FAILED - no venv-dembones")
        else:
            try:
                out = run_dembones(db_py, rest, frames, polys, bones, tmp)
                mine = metrics.dem_bones_rmse(out["reconstruction"], frames)
                db = rmse_and_seconds(out)
                line(f"   {bones:2d} bones  Dem Bones RMSE {float(out['rmse']):.4f} (published {pub}; recomputed here "
                     f"{mine:.4f}), {int(out['bones'])} bones used, {float(out['seconds']):.2f} s, "
                     f"peak RSS {float(out['rss_kb']) / 1024:.0f} MB")
            except RuntimeError as e:
                line(f"   {bones:2d} bones  Dem Bones: FAILED - {e}")
        for alpha, every_scan in BONE_ANIM_RUNS:
            what = f"ours, alpha {alpha:g}" + (" (default)" if alpha == 100 else ", no joint prior (data-fit setting)")
            options = {"alpha": alpha} if alpha == 100 else {"alpha": alpha, "joint_prior": 0.0}
            if every_scan:
                what += ", learned from every scan"
                options["key_scans"] = None
            label = f"dem_bones {bones} alpha {alpha:g}" + (" every scan" if every_scan else "")
            got = learn_or_fail((have_learner, why, failures), label,
                                f"   {bones:2d} parts  {what}", frames, tris, bones, tmp, options)
            if got is not None:
                model, poses, meas = got
                _, rmse = surface_stats(frames, model, poses)
                line(f"   {bones:2d} parts  {what}: RMSE {rmse:.4f}, {model.skeleton.num_bones} parts, "
                     f"{wall_split(meas)}, {learn_detail(meas, len(frames))}, "
                     f"peak RSS {meas['rss_peak_kb'] / 1024:.0f} MB{versus(db, rmse, meas)}")
    if first_mh is None:                                     # section 1 not run (yet): its first sequence
        from articula.sample_scenes.registered import posed_sequence
        rig, shape, skin = makehuman_cases(args.quick)[0]
        train, faces, _ = posed_sequence(rig, shape, TRAIN_POSES, "rom", skin, seed=0)
        first_mh = (train, faces, f"{rig} / {shape} / {skin}")
    train, faces, label = first_mh
    mine = ours.get("makehuman")
    k = mine[0] if mine else (args.parts or 19)
    note = ("our part count" if mine else "--parts" if args.parts
            else "no learned part count: 19 parts, the spec's J + 1")
    line(f"-- MakeHuman {label}: {train.shape[0]} frames x {train.shape[1]} vertices, {k} bones ({note}); "
         f"Dem Bones gets the first scan as its rest mesh, as learn_rig sees only scans")
    out = None
    if db_py is not None:
        try:
            out = run_dembones(db_py, train[0], train, faces, k, tmp)
            line(f"   Dem Bones RMSE {float(out['rmse']) * 1000:.2f} mm, {int(out['bones'])} bones used, "
                 f"{float(out['seconds']):.1f} s, peak RSS {float(out['rss_kb']) / 1024:.0f} MB")
        except RuntimeError as e:
            line(f"   Dem Bones: FAILED - {e}")
    if mine:
        db = None if out is None else rmse_and_seconds(out)
        line(f"   ours (section 1, first case) RMSE {mine[1] * 1000:.2f} mm, {wall_split(mine[2])}"
             f"{versus(db, mine[1], mine[2])}")
    else:
        line(f"   ours: FAILED - no learned model for this sequence ({why or 'see section 1'}); no numbers")
        failures.append("dem_bones makehuman")


def section_tube(args, tmp, have_learner, why, failures):
    from articula.sample_scenes.tube_scans import hybrid_truth
    import _learn_metrics as metrics
    line("== 4. tube body (synthetic, hybrid-skin ground truth; sample_scenes/tube_scans.py)")
    truth, true_poses, train = hybrid_truth(8, seed=0)
    test = hybrid_truth(5, seed=1)[2][1:]                  # scan 0 of every sequence is the rest pose
    k = truth.skeleton.num_bones
    line(f"-- {len(train)} training + {len(test)} held-out scans x {train.shape[1]} vertices, {k} true parts")
    if not args.no_reference:
        stats, fit, sec = held_out(truth, test)
        line(f"   reference: true model, held-out poses by pose_fit (expect 0): {stats_text(stats)}; "
             f"{int(fit.converged.sum())}/{len(test)} converged")
    got = learn_or_fail((have_learner, why, failures), "tube", "   ours", train, truth.faces, k, tmp)
    if got is None:
        return
    model, poses, meas = got
    tr, _ = surface_stats(train, model, poses)
    ho, hfit, _ = held_out(model, test)
    ref = metrics.posed_joints(truth.skeleton, true_poses)[:, 1:]
    je = joint_errors(posed_joints(model, poses), ref) * 1000
    line(f"   ours: {model.skeleton.num_bones} parts, {meas['wall_s']:.1f} s wall, {meas['cpu_s']:.1f} s CPU, "
         f"peak RSS {meas['rss_peak_kb'] / 1024:.0f} MB")
    line(f"   ours training error: {stats_text(tr)}")
    line(f"   ours held-out error ({len(test)} poses fitted by pose_fit): {stats_text(ho)}; "
         f"{int(hfit.converged.sum())}/{len(test)} converged")
    line(f"   ours joint centres vs the true joints ({len(je)} matched among {ref.shape[1]}; averaged over the "
         f"scans): mean {je.mean():.1f}  median {np.median(je):.1f}  max {je.max():.1f} mm")


# ------------------------------------------------------------------------------------------ main

def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--child-learn"]:
        runs.child_learn(argv[1], argv[2])
        return 0
    p = argparse.ArgumentParser(
        prog="bench learn", description="Rig learning (learn_rig) against ground truth and Dem Bones.  Section 0 "
        "(issue19, first by default; --order issue19 alone writes bench/results/learn-issue19.txt): per case "
        "learn_rig at its defaults and Dem Bones at our part count, with the RMSE and wall-time ratios, the "
        "worst joint outside the surface, mirror and leg pairs, empty parts, major joints within 2 cm, and "
        "each target met or missed.  bench/bench_learn.py's docstring describes every section.")
    p.add_argument("--quick", action="store_true", help="a subset (module docstring)")
    p.add_argument("--no-dembones", action="store_true", help="skip the Dem Bones runs")
    p.add_argument("--out", default=None, help="results file (default bench/results/learn[-quick].txt, "
                                                 "learn-issue19[-quick].txt for --order issue19)")
    p.add_argument("--parts", type=int, default=0,
                   help="parts for the MakeHuman runs of section 1 (0: learn_rig chooses; section 0 always lets it)")
    p.add_argument("--learn-timeout", type=float, default=None, help="seconds per learn_rig run (default none)")
    p.add_argument("--learn-iterations", type=int, default=0,
                   help="learn_rig max_iterations (outer rounds; 0: the learner's default)")
    p.add_argument("--bone-counts", type=lambda t: [int(x) for x in t.split(",")], default=None,
                   help="bone/part counts on Dem Bones' Bone_Anim (default 5,10,20; --quick 5,10)")
    p.add_argument("--mh-cases", type=int, default=0, help="only the first N MakeHuman cases (0: all)")
    p.add_argument("--mh-skip", type=int, default=0, help="skip the first N MakeHuman cases")
    p.add_argument("--no-reference", action="store_true", help="skip the exact-model pose_fit reference rows")
    p.add_argument("--gt", type=lambda t: t.split(","), default=None,
                   help="skinning_gt rigs (default cylinder,wolf; --quick cylinder)")
    p.add_argument("--order", default="issue19,makehuman,skinning_gt,dembones",
                   help="sections to run, in this order (comma-separated): issue19 (section 0: every case at "
                        "default options next to Dem Bones at our part count, issue 19's figures and targets), "
                        "makehuman, skinning_gt, dembones; also tube, the synthetic tube body with known truth, "
                        "not in the default")
    p.add_argument("--cases", type=lambda t: [x.strip() for x in t.split(",") if x.strip()], default=None,
                   help=f"issue19 cases (default {','.join(i19.CASES)}; --quick {','.join(i19.QUICK_CASES)})")
    args = p.parse_args(argv)
    runs.LEARN_TIMEOUT[0] = args.learn_timeout
    runs.LEARN_ROUNDS[0] = args.learn_iterations
    order = [x.strip() for x in args.order.split(",") if x.strip()]
    unknown = set(order) - {"issue19", "makehuman", "skinning_gt", "dembones", "tube"}
    if unknown:
        p.error(f"--order: unknown sections {sorted(unknown)}")
    if set(args.cases or ()) - set(i19.CASES):
        p.error(f"--cases: unknown cases {sorted(set(args.cases) - set(i19.CASES))} (known: {', '.join(i19.CASES)})")
    name = "learn-issue19" if order == ["issue19"] else "learn"
    out_path = args.out or os.path.join(HERE, "results", f"{name}-quick.txt" if args.quick else f"{name}.txt")
    tee = Tee(sys.stdout, out_path)
    real, sys.stdout = sys.stdout, tee
    failures = []
    t_start = time.perf_counter()
    try:
        line(f"command: ./run bench learn {' '.join(argv)}".rstrip())
        line(f"date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC")
        line(f"machine: {machine()}")
        rev = subprocess.run(["git", "-C", REPO, "log", "-1", "--format=%h %cd", "--date=format:%H:%M"],
                             capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--", "solver"], capture_output=True,
                               text=True).stdout.split("\n")
        dirty = [ln[3:] for ln in dirty if ln.strip()]
        line(f"code: commit {rev or '?'}" + (f"; uncommitted changes included in {len(dirty)} solver files: "
                                             f"{', '.join(dirty)}" if dirty else "; no uncommitted solver changes"))
        have, why = learner_status()
        line(f"learner: {'solver.learn.pipeline.learn_rig' if have else 'MISSING (' + why + ')'}")
        db_py = None
        if not args.no_dembones:
            try:
                db_py = dembones_python()
                line(f"Dem Bones: {DEMBONES_PIN} in {os.path.dirname(os.path.dirname(db_py))}")
            except (RuntimeError, subprocess.CalledProcessError) as e:
                line(f"Dem Bones: FAILED to set up - {e}")
        ours, first = {}, None
        if args.parts:
            line(f"MakeHuman part count: {args.parts} (--parts)")
        if args.learn_iterations:
            line(f"learn_rig outer rounds: at most {args.learn_iterations} (--learn-iterations)")
        if args.learn_timeout:
            line(f"learn_rig time limit: {args.learn_timeout:.0f} s per run (--learn-timeout)")
        with tempfile.TemporaryDirectory(prefix="articula_bench_learn_") as tmp:
            for section in order:
                if section == "issue19":
                    i19.section_issue19(args, tmp, have, why, failures, db_py)
                elif section == "makehuman":
                    first = section_makehuman(args, tmp, have, why, failures, ours)
                elif section == "skinning_gt":
                    section_skinning_gt(args, tmp, have, why, failures, db_py)
                elif section == "tube":
                    section_tube(args, tmp, have, why, failures)
                elif not args.no_dembones:
                    section_dembones(args, tmp, have, why, failures, db_py, first, ours)
        line(f"total bench time {time.perf_counter() - t_start:.0f} s; peak RSS of the bench process "
             f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
        if failures:
            line(f"FAILED rows ({len(failures)}): {', '.join(failures)}")
    finally:
        sys.stdout = real
        tee.close()
    print(f"(results written to {os.path.relpath(out_path, REPO)})")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
