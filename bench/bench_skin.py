"""Hybrid swing/twist skin next to plain LBS on one core (frames/s), and the candy-wrapper figures.

Hybrid swing/twist skinning (solver) next to plain LBS in the same run, on one core, plus the
candy-wrapper figures on a twisted / swung tube.

Threads: BLAS/OpenMP pools are read when numpy loads, so unless OPENBLAS_NUM_THREADS=1 is already set
this benchmark re-runs itself in a child Python with OMP_NUM_THREADS = OPENBLAS_NUM_THREADS =
MKL_NUM_THREADS = 1 (threadpoolctl is not installed).

Usage: ./run bench skin   (defaults), or with options:
       ~/.cache/articula/venv-bpy52/bin/python bench/bench_skin.py [--vertices 13380] [--frames 100] [--repeats 5]
"""
import argparse
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _single_threaded() -> bool:
    return all(os.environ.get(v) == "1" for v in THREAD_VARS)


def _rerun_single_threaded(argv) -> int:
    env = dict(os.environ, **{v: "1" for v in THREAD_VARS})
    return subprocess.run([sys.executable, os.path.abspath(__file__), *argv], env=env).returncode


def _best_time(fn, repeats):
    import time
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _speed(args):
    import numpy as np
    import scipy.sparse as sp
    from articula.solver.rig import jacobians
    from articula.solver.rig import kinematics
    from articula.solver.rig import skinning
    from articula.sample_scenes import synthetic

    model = synthetic.random_model(args.vertices, seed=0)
    model.validate()
    poses = synthetic.random_poses(args.frames, model.skeleton.num_bones, seed=1)
    B = model.skeleton.num_bones
    # LBS weights with the same sparsity as the hybrid skin: anchor bone + its children (<= 4 non-zeros)
    w = model.swing_weights.astype(np.float64)
    w[np.arange(len(w)), model.anchor] += 1 - w.sum(axis=1)
    dense, sparse = w, sp.csr_matrix(w)
    nnz = np.diff(sparse.indptr)
    _common.report("setup", f"{args.vertices} vertices x {args.frames} frames, {B} bones, "
                   f"mean {nnz.mean():.2f} / max {nnz.max()} influences per vertex (LBS)")

    def lbs(weights):
        Rm, tm = kinematics.forward_kinematics(model.skeleton, poses)
        return skinning.lbs(model.rest_vertices, weights, Rm, tm)

    t_hyb = _best_time(lambda: skinning.hybrid_skin(model, poses), args.repeats)
    t_dense = _best_time(lambda: lbs(dense), args.repeats)
    t_sparse = _best_time(lambda: lbs(sparse), args.repeats)
    t_aff = _best_time(lambda: skinning.affine_form(model, poses), max(1, args.repeats // 2))
    n = args.frames
    _common.report("hybrid_skin", n / t_hyb, "frames/s", "FK included; target >= 100")
    _common.report("lbs dense weights", n / t_dense, "frames/s", "FK included")
    _common.report("lbs sparse weights", n / t_sparse, "frames/s", "FK included")
    _common.report("affine_form", n / t_aff, "frames/s", "A (N,V,3,3), b (N,V,3)")
    best_lbs = min(t_dense, t_sparse)
    _common.report("speed ratio hybrid / best lbs", best_lbs / t_hyb, "", "target >= 0.333")
    one = synthetic.random_poses(1, B, seed=2)
    groups = skinning.AnchorGroups(model)
    t_one = _best_time(lambda: skinning.hybrid_skin(model, one, groups), args.repeats)
    t_jac = _best_time(lambda: jacobians.pose_jacobian(model, one, groups), args.repeats)
    _common.report("hybrid_skin one frame (AnchorGroups reused)", 1e3 * t_one, "ms")
    _common.report("pose_jacobian one frame", 1e3 * t_jac, "ms",
                   f"{t_jac / t_one:.3g} x one hybrid_skin frame; P = {4 + 3 * B} columns")
    P = 4 + 3 * B

    def central_differences():
        for j in range(P):
            d = np.zeros((1, P))
            d[0, j] = 1e-6
            skinning.hybrid_skin(model, jacobians.apply_pose_increment(one, d), groups)
            skinning.hybrid_skin(model, jacobians.apply_pose_increment(one, -d), groups)

    t_fd = _best_time(central_differences, 1)
    _common.report("central-difference pose Jacobian one frame", 1e3 * t_fd, "ms",
                   f"analytic is {t_fd / t_jac:.3g} x faster")


def _tube_volume(posed, tube, rings, sectors):
    """Enclosed volume of the tube with its end rings capped by triangle fans to their centroids."""
    import numpy as np
    pts = posed
    tris = [pts[tube.faces]]
    j = np.arange(sectors)
    first, last = j, (rings - 1) * sectors + j
    for ring, flip in ((first, True), (last, False)):
        c = pts[ring].mean(axis=0)
        a, b = pts[ring], pts[np.roll(ring, -1)]
        cap = np.stack([np.broadcast_to(c, a.shape), b, a] if flip else [np.broadcast_to(c, a.shape), a, b], axis=1)
        tris.append(cap)
    t = np.concatenate(tris)
    return abs(np.einsum("ti,ti->t", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def _ring_area(ring):
    """Vector area |½ Σ p_i × p_(i+1)| of a closed polygon (R, 3)."""
    import numpy as np
    c = ring - ring.mean(axis=0)
    return 0.5 * float(np.linalg.norm(np.cross(c, np.roll(c, -1, axis=0)).sum(axis=0)))


def _candy_wrapper():
    import numpy as np
    from articula.solver.rig import kinematics
    from articula.solver.rig import skinning
    from articula.sample_scenes import synthetic
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat

    rings, sectors = 81, 64
    tube = synthetic.tube_model(rings=rings, sectors=sectors, swing_ramp=True)
    ramp = tube.twist_weights[:, 1].astype(np.float64)
    w2 = np.stack([1 - ramp, ramp], axis=1)
    rest_vol = _tube_volume(tube.rest_vertices, tube, rings, sectors)

    def pose(rotvec):
        q = np.array([[[1.0, 0, 0, 0], rotvec_to_quat(rotvec)]])
        return Poses(q, np.zeros((1, 3)), np.ones(1))

    def deform(p):
        Rm, tm = kinematics.forward_kinematics(tube.skeleton, p)
        return {"lbs": skinning.lbs(tube.rest_vertices, w2, Rm, tm)[0],
                "dqs": skinning.dqs(tube.rest_vertices, w2, Rm, tm)[0],
                "hybrid": skinning.hybrid_skin(tube, p)[0]}

    twisted = deform(pose([0, np.pi, 0]))                      # bone Y = world X
    for name, pts in twisted.items():
        r = np.linalg.norm(pts[:, 1:], axis=1)
        _common.report(f"180 deg twist min radius ratio {name}", f"{r.min():.12f}", "", "hybrid target >= 0.999")
    swung = deform(pose([np.pi / 2, 0, 0]))
    _common.report("90 deg swing max |hybrid - lbs|", float(np.abs(swung["hybrid"] - swung["lbs"]).max()), "m",
                   "hybrid equals LBS: no bulge added")
    joint_ring = (rings // 2) * sectors + np.arange(sectors)            # the ring at x = 0 (the joint)
    rest_area = _ring_area(tube.rest_vertices[joint_ring])
    for name, pts in swung.items():
        _common.report(f"90 deg swing volume ratio {name}", f"{_tube_volume(pts, tube, rings, sectors) / rest_vol:.6f}")
        _common.report(f"90 deg swing joint cross-section area ratio {name}",
                       f"{_ring_area(pts[joint_ring]) / rest_area:.6f}")


def main(argv) -> int:
    if not _single_threaded():
        return _rerun_single_threaded(argv)
    ap = argparse.ArgumentParser(prog="bench skin")
    ap.add_argument("--vertices", type=int, default=13380)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    _common.report("threads", "1", "", "OMP/OPENBLAS/MKL_NUM_THREADS=1 set before numpy loaded")
    _speed(args)
    _candy_wrapper()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
