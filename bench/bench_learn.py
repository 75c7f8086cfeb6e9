"""Rig learning (solver.learn.learn_rig): accuracy and time per stage, and a peer comparison with Dem Bones.

    ./run bench learn                              # synthetic tube body (known truth), 8 parts
    ./run bench learn --data dembones --parts 5 10 20 [--peer]   # Dem Bones' public "Bone" sequence
    ./run bench learn --data makehuman --frames 12 --parts 19    # sample_scenes.registered (MakeHuman)

Errors: every input vertex to the posed model surface (exact point-to-triangle), in mm when the data is in
metres (the Dem Bones sequence has no unit; its mesh is ~3.7 units wide).  --peer runs Dem Bones (LBS,
py-dem-bones) from a separate venv (default ~/.cache/articula/venv-dembones, never bundled) on the same
frames and evaluates its reconstruction with the same metric.
"""
import _common  # noqa: F401  (makes `import articula` work)

import argparse
import json
import os
import subprocess
import tempfile
import time

import numpy as np

from articula.solver.learn import learn_rig
from articula.solver.surface_distance import distance_to_surface, error_statistics

DEMBONES = os.path.join(os.path.dirname(_common.REPO), "shared", "data", "dem_bones")
PEER_VENV = os.path.expanduser("~/.cache/articula/venv-dembones/bin/python")


def _obj_quads(path):
    v, f = [], []
    for line in open(path):
        s = line.split()
        if s and s[0] == "v":
            v.append([float(x) for x in s[1:4]])
        elif s and s[0] == "f":
            f.append([int(x.split("/")[0]) - 1 for x in s[1:]])
    return np.array(v), f


def _triangles(polys):
    return np.array([[p[0], p[i], p[i + 1]] for p in polys for i in range(1, len(p) - 1)], dtype=np.int32)


def _surface_stats(frames, posed, faces):
    d = np.concatenate([distance_to_surface(frames[m], posed[m], faces) for m in range(len(frames))])
    return {k: (v if k == "count" else 1e3 * v) for k, v in error_statistics(d).items()}


def _print_result(tag, stats, seconds, extra=""):
    _common.report(f"{tag} surface error mean", stats["mean"], "mm", f"std {stats['std']:.3g}, median "
                   f"{stats['median']:.3g}, MAD {stats['mad']:.3g}, IQR {stats['iqr']:.3g}, max {stats['max']:.3g}")
    _common.report(f"{tag} time", seconds, "s", extra)


def run_learn(tag, frames, faces, parts, args):
    t0, c0 = time.perf_counter(), time.process_time()
    res = learn_rig(frames, faces, parts=parts, max_iterations=args.iterations, bcd_sweeps=args.bcd_sweeps,
                    gn_iterations=args.gn_iterations, seed=args.seed, alpha=args.alpha,
                    symmetry=not args.no_symmetry)
    seconds = time.perf_counter() - t0
    rep = res.report
    timing = ", ".join(f"{k} {v:.1f}s" for k, v in rep["timings_s"].items() if k != "total")
    timing += f"; process CPU {time.process_time() - c0:.1f}s (wall-clock stages are inflated on a busy machine)"
    _print_result(f"{tag} articula", rep["surface_error_mm"], seconds, timing)
    _common.report(f"{tag} articula objective", rep["objective_log"][-1][1], "",
                   f"from {rep['objective_log'][0][1]:.4g}; {rep['iterations']} rounds, converged={rep['converged']}")
    return res


def run_peer(tag, rest, frames, polys, faces, bones):
    if not os.path.exists(PEER_VENV):
        print(f"{tag} dem bones: skipped (no {PEER_VENV}; pip install py-dem-bones into a separate venv)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        paths = [os.path.join(tmp, n) for n in ("rest.npy", "frames.npy", "faces.npy", "out.npy")]
        np.save(paths[0], rest)
        np.save(paths[1], frames)
        np.save(paths[2], np.array(polys))
        subprocess.run([PEER_VENV, os.path.join(os.path.dirname(__file__), "dembones_peer.py"), *paths[:3],
                        str(bones), paths[3]], check=True)
        recon = np.load(paths[3])
        meta = json.load(open(paths[3] + ".json"))
    _print_result(f"{tag} dem-bones", _surface_stats(frames, recon, faces), meta["seconds"],
                  f"{meta['bones_found']} bones, LBS, 4 influences, 30 iterations")


def bench_dembones(args):
    frames = np.load(os.path.join(DEMBONES, "Bone_Anim_positions_400x754x3.npy")).astype(np.float64)[::args.step]
    rest, polys = _obj_quads(os.path.join(DEMBONES, "Bone_Geom_rest.obj"))
    faces = _triangles(polys)
    print(f"dem bones 'Bone' sequence: {len(frames)} frames (every {args.step}th of 400), {frames.shape[1]} vertices")
    for k in args.parts:
        run_learn(f"k={k}", frames, faces, k, args)
        if args.peer:
            run_peer(f"k={k}", rest, frames, polys, faces, k)


def bench_tube(args):
    import sys
    sys.path.insert(0, os.path.join(_common.REPO, "tests", "solver"))
    from learn_data import hybrid_truth
    truth, poses, scans = hybrid_truth(args.frames, seed=args.seed)
    print(f"tube body: {len(scans)} scans, {truth.num_vertices} vertices, hybrid skin ground truth")
    res = run_learn("tube", scans, truth.faces, args.parts[0] if args.parts else 8, args)
    from articula.solver.kinematics import forward_kinematics
    Rm, tm = forward_kinematics(truth.skeleton, poses)
    r, par = res.report["rest_scan"], np.maximum(truth.skeleton.parents, 0)
    joints = np.einsum("bij,bj->bi", Rm[r, par], truth.skeleton.heads) + tm[r, par]
    d = np.array([np.linalg.norm(joints[1:] - h, axis=1).min() for h in res.model.skeleton.heads[1:]]) * 1e3
    _common.report("tube joint error", float(d.max()), "mm", f"max over joints; median {np.median(d):.3g} mm")


def bench_makehuman(args):
    from articula.sample_scenes.registered import posed_sequence
    t0 = time.perf_counter()
    verts, faces, gt = posed_sequence(n_poses=args.frames, skin="hybrid", seed=args.seed)
    print(f"makehuman registered: {verts.shape[0]} scans, {verts.shape[1]} vertices (generated in "
          f"{time.perf_counter() - t0:.1f}s)")
    res = run_learn("makehuman", verts, faces, args.parts[0] if args.parts else 19, args)
    truth = gt["posed_heads"][res.report["rest_scan"]]           # true joints in the rest scan
    d = np.array([np.linalg.norm(truth - h, axis=1).min() for h in res.model.skeleton.heads[1:]]) * 1e3
    _common.report("makehuman joint to nearest true joint", float(np.median(d)), "mm",
                   f"median over {len(d)} learned joints; max {d.max():.3g} mm; rig has {len(truth)} true joints")


def main(argv):
    p = argparse.ArgumentParser(prog="bench learn")
    p.add_argument("--data", choices=("tube", "dembones", "makehuman"), default="tube")
    p.add_argument("--parts", type=int, nargs="*", default=None)
    p.add_argument("--frames", type=int, default=8, help="scans for tube / makehuman")
    p.add_argument("--step", type=int, default=10, help="dembones: every step-th frame")
    p.add_argument("--iterations", type=int, default=3)
    p.add_argument("--bcd-sweeps", type=int, default=3)
    p.add_argument("--gn-iterations", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--alpha", type=float, default=100.0, help="shape-conformance weight")
    p.add_argument("--no-symmetry", action="store_true")
    p.add_argument("--peer", action="store_true", help="also run Dem Bones (separate venv)")
    args = p.parse_args(argv)
    if args.data == "dembones":
        args.parts = args.parts or [5, 10, 20]
        bench_dembones(args)
    elif args.data == "makehuman":
        bench_makehuman(args)
    else:
        bench_tube(args)
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main(sys.argv[1:]))
