"""Speed of rig learning on MakeHuman: time per stage, wall/CPU, peak memory, accuracy.

Speed of rig learning (solver.learn.pipeline.learn_rig) on MakeHuman: per-stage time, wall/CPU, peak memory, accuracy.

    ./run bench learn_speed                          # 13,380 v x 30 scans, 19 parts, default rounds
    ./run bench learn_speed --frames 10 --iterations 3 --gn-iterations 3 --bcd-sweeps 3
    ./run bench learn_speed --rig game_engine --shape male,thin --skin lbs
    ./run bench learn_speed --bone-anim --parts 10 --threads 1     # Dem Bones' example, data-fit setting
    ./run bench learn_speed --subdivide                            # 53,514 v x 30 scans (step (a) on a subset)
    ./run bench learn_speed --subdivide --joint-vertices 0         # the same with step (a) on all vertices

Data: ``sample_scenes.registered.posed_sequence(rig="cmu_mb", shape="female", n_poses=N, motion="rom",
skin="hybrid", seed=0)`` (rig, shape and skin selectable: the cases of ``bench learn``).  Prints the time of every stage (``report["timings_s"]``), total wall and process
CPU time, the peak resident memory of the process (``resource.getrusage``, includes the data) and the
training error (mean scan-vertex-to-posed-surface distance, mm) so that speed never silently buys worse
accuracy.  ``--bone-anim``: Dem Bones' Bone_Anim (400 frames x 754 vertices, ``../shared/data/dem_bones``)
with the data-fit setting of ``bench learn`` (α = 1, no joint prior), also printing its RMSE as Dem Bones
defines it; ``--threads`` sets learn_rig's solver threads (default: one per core), ``--key-scans`` its key
scans, ``--no-warm-start`` drops the warm-start rounds.  Unit of work measured in the same run: one ``hybrid_skin`` evaluation of all scans with the
learned model; the total is also printed as a multiple of it, which is comparable across machines/loads.
"""
import argparse
import os
import resource
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

from articula.solver.learn.pipeline import learn_rig  # noqa: E402
from articula.solver.rig.skinning import hybrid_skin  # noqa: E402


def _peak_rss_gib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20        # Linux: KiB


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench learn_speed")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--parts", type=int, default=19)
    ap.add_argument("--iterations", type=int, default=None, help="learn_rig max_iterations (default: its own)")
    ap.add_argument("--gn-iterations", type=int, default=None)
    ap.add_argument("--bcd-sweeps", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rig", default="cmu_mb", help="MakeHuman skeleton: cmu_mb or game_engine")
    ap.add_argument("--shape", default="female", help="MakeHuman shape, e.g. female, male,thin")
    ap.add_argument("--skin", default="hybrid", help="skin that poses the scans: hybrid or lbs")
    ap.add_argument("--bone-anim", action="store_true",
                    help="Dem Bones' Bone_Anim instead of MakeHuman, alpha 1 and no joint prior")
    ap.add_argument("--threads", type=int, default=None, help="learn_rig workers (default: one per core)")
    ap.add_argument("--key-scans", type=int, default=None, help="learn_rig key_scans (default: its own)")
    ap.add_argument("--no-warm-start", action="store_true", help="learn_rig warm_start=() (no warm-start rounds)")
    ap.add_argument("--joint-vertices", type=int, default=None,
                    help="learn_rig joint_vertices (step (a) on a vertex subset; 0: all vertices)")
    ap.add_argument("--subdivide", action="store_true",
                    help="midpoint-subdivide the MakeHuman meshes once (53,514 v), as bench learn_memory's subdiv1")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    if args.bone_anim:
        from _learn_runs import bone_anim
        _, verts, _, faces = bone_anim()
    else:
        from articula.sample_scenes.registered import posed_sequence
        verts, faces, _ = posed_sequence(rig=args.rig, shape=args.shape, n_poses=args.frames, motion="rom",
                                         skin=args.skin, seed=args.seed)
        if args.subdivide:
            from bench_learn_memory import subdivide
            verts, faces = subdivide(np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int32))
    verts = np.asarray(verts, dtype=np.float64)
    _common.report("data", f"{verts.shape[0]} scans x {verts.shape[1]} vertices", "",
                   f"loaded in {time.perf_counter() - t0:.1f}s; peak RSS so far {_peak_rss_gib():.2f} GiB")
    options = {k: v for k, v in (("max_iterations", args.iterations), ("gn_iterations", args.gn_iterations),
                                 ("bcd_sweeps", args.bcd_sweeps), ("workers", args.threads),
                                 ("key_scans", args.key_scans), ("joint_vertices", args.joint_vertices))
               if v is not None}
    if args.no_warm_start:
        options["warm_start"] = ()
    if args.bone_anim:
        options.update(alpha=1.0, joint_prior=0.0)
    t0, c0 = time.perf_counter(), _common.cpu_seconds()
    res = learn_rig(verts, faces, parts=args.parts, seed=args.seed, **options)
    wall, cpu = time.perf_counter() - t0, _common.cpu_seconds() - c0
    rep = res.report
    for stage, seconds in rep["timings_s"].items():
        if stage != "total":
            _common.report(f"stage {stage}", seconds, "s", "wall")
    _common.report("learn_rig wall", wall, "s", f"options {options or 'defaults'}, {args.parts} parts")
    _common.report("learn_rig CPU", cpu, "s", f"process time ({rep['workers']} threads) + forked helper processes")
    _common.report("learning (wall without the report)", wall - rep["timings_s"]["report"], "s")
    _common.report("peak memory", _peak_rss_gib(), "GiB", "ru_maxrss of the process")
    t1 = time.perf_counter()
    for _ in range(3):
        hybrid_skin(res.model, res.poses)
    unit = (time.perf_counter() - t1) / 3
    _common.report("unit: one hybrid_skin of all scans", unit, "s", f"learn_rig = {wall / unit:.0f} units")
    err = rep["surface_error_mm"]
    _common.report("training surface error mean", err["mean"], "1e-3 file units" if args.bone_anim else "mm",
                   f"median {err['median']:.3g}, max {err['max']:.3g}; vertex RMS {rep['vertex_rms_mm']:.3g} mm")
    if args.bone_anim:
        from _learn_metrics import dem_bones_rmse
        _common.report("RMSE (Dem Bones' definition)", dem_bones_rmse(hybrid_skin(res.model, res.poses), verts), "",
                       f"learned from {len(rep['key_scans'])} of {len(verts)} scans")
    _common.report("rounds", rep["iterations"], "", f"converged={rep['converged']} ({rep['stopped']}), objective "
                   f"{rep['objective_log'][0][1]:.6g} -> {rep['objective_log'][-1][1]:.6g}; step (a) on "
                   f"{rep['joint_vertices']} vertices in {rep['coarse_rounds']} rounds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
