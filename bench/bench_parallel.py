"""The solver's threads: one worker against two on the same inputs, and BLAS on one thread or two.

Usage: ``./run bench parallel [--scans 30] [--repeats 3]``.

On the MakeHuman subject (``cmu_mb`` female, 13,380 vertices, hybrid skin) in ``--scans`` range-of-motion
poses, best wall time of ``--repeats`` runs with ``solver.parallel.using(1)`` and ``using(2)``:

* ``hybrid_skin`` of every pose (frames split into chunks over the workers);
* ``per_vertex_scan_distances``: every posed vertex shifted by 2 mm noise to the surface of its pose (what
  the learned rig's error report measures), batches over the workers.

Then ``single_blas_thread``: the process CPU time of ``X.T @ X`` for X (12,000 x 30), 200 times, with
OpenBLAS as loaded (its own thread count) and inside the block (one thread).  Results are identical in
both settings (checked and printed); the times depend on the load of the shared machine.
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # the bench command loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

from articula.sample_scenes.registered import make_poses  # noqa: E402
from articula.sample_scenes.subjects import make_subject  # noqa: E402
from articula.solver import parallel  # noqa: E402
from articula.solver.geometry.surface_distance import per_vertex_scan_distances  # noqa: E402
from articula.solver.rig.skinning import hybrid_skin  # noqa: E402


def _one_vs_two(label, fn, repeats, note):
    """Time ``fn`` with one worker and with two; report both and whether the results agree."""
    with parallel.using(1):
        t1, r1 = _common.best_time(fn, repeats)
    with parallel.using(2):
        t2, r2 = _common.best_time(fn, repeats)
    diff = float(np.abs(np.asarray(r1) - np.asarray(r2)).max())
    _common.report(f"{label}: two workers", t2, "s", f"one worker {t1:.3f} s ({t1 / t2:.2f}x); {note}; "
                                                    f"largest difference {diff:.1e}")


def _blas(repeats):
    x = np.random.default_rng(0).standard_normal((12_000, 30))

    def products():
        t0 = time.process_time()
        for _ in range(200):
            out = x.T @ x
        return time.process_time() - t0, out

    as_loaded = min(products()[0] for _ in range(repeats))
    with parallel.single_blas_thread():
        one = min(products()[0] for _ in range(repeats))
    _common.report("X.T @ X, X 12,000 x 30, 200 times: one BLAS thread", one, "s CPU",
                   f"OpenBLAS as loaded {as_loaded:.3f} s CPU")


def main(argv) -> int:
    ap = argparse.ArgumentParser(prog="./run bench parallel", description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=30, help="range-of-motion poses (default 30)")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many runs (default 3)")
    args = ap.parse_args(argv)
    subject = make_subject("cmu_mb", "female")
    model = subject.hybrid_model()
    poses = make_poses(subject, "rom", args.scans, 0)
    posed = hybrid_skin(model, poses)
    noisy = posed + np.random.default_rng(1).normal(0.0, 0.002, posed.shape)
    size = f"{model.num_vertices} vertices x {args.scans} poses, {os.cpu_count()} cores"
    _one_vs_two("hybrid skin", lambda: hybrid_skin(model, poses), args.repeats, size)
    _one_vs_two("scan-to-surface distances", lambda: per_vertex_scan_distances(noisy, posed, model.faces),
                args.repeats, size)
    _blas(args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
