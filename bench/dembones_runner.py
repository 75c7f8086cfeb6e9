"""Runs Dem Bones (the ``py-dem-bones`` wheel) on one mesh sequence, in its OWN virtual environment.

The Articula benchmark ``bench_learn.py`` starts this script with ``$ARTICULA_HOME/venv-dembones/bin/python``
in a subprocess; the extension never imports py-dem-bones.  It uses only numpy and py_dem_bones.

    python dembones_runner.py IN.npz OUT.npz

IN.npz: ``rest (V, 3)``, ``frames (N, V, 3)``, polygons as ``face_sizes (F,)`` and ``corners (Σ sizes,)`` (vertex
indices, 0-based), ``bones`` (target count) and optional
parameters (defaults = Dem Bones' own defaults, the ones its published example ran with: nIters 30,
nInitIters 10, nTransIters 5, nWeightsIters 3, transAffine 10, transAffineNorm 4, nnz 8,
weightsSmooth 1e-4, weightsSmoothStep 1).
OUT.npz: ``weights (B, V)``, ``transforms (N, B, 4, 4)`` (column vectors: x' = M x), ``reconstruction (N, V, 3)``,
``rmse`` (Dem Bones' own ``rmse()``), ``seconds`` (wall time of ``compute()`` only), ``cpu_seconds`` (CPU
time of all its threads during ``compute()``), ``bones`` (the count
it actually used; its initialisation may give fewer than asked), ``version``, ``rss_kb`` (peak resident
memory of this process, kB).
"""
import resource
import sys
import time

import numpy as np

DEFAULTS = dict(nIters=30, nInitIters=10, nTransIters=5, nWeightsIters=3, transAffine=10.0,
                transAffineNorm=4.0, nnz=8, weightsSmooth=1e-4, weightsSmoothStep=1.0)


def main(src, dst):
    import py_dem_bones
    from py_dem_bones._py_dem_bones import DemBones

    data = np.load(src)
    rest = np.asarray(data["rest"], dtype=np.float64)
    frames = np.asarray(data["frames"], dtype=np.float64)
    N, V = frames.shape[:2]
    db = DemBones()
    for key, value in DEFAULTS.items():
        setattr(db, key, type(value)(data[key]) if key in data.files else value)
    db.nV, db.nF, db.nS, db.nB = V, N, 1, int(data["bones"])
    db.fStart = np.array([0, N], dtype=np.int32)
    db.subjectID = np.zeros(N, dtype=np.int32)
    db.u = np.ascontiguousarray(rest.T)                                   # (3, V)
    db.v = np.ascontiguousarray(frames.transpose(0, 2, 1).reshape(3 * N, V))
    sizes, corners = data["face_sizes"], data["corners"]
    db.fv = [c.tolist() for c in np.split(corners.astype(np.int64), np.cumsum(sizes)[:-1])]
    t0, c0 = time.perf_counter(), time.process_time()
    db.compute()
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    B = int(db.nB)
    weights = np.asarray(db.get_weights(), dtype=np.float64).reshape(B, V)
    m = np.asarray(db.m, dtype=np.float64).reshape(N, 4, B, 4).transpose(0, 2, 1, 3)
    posed = np.einsum("nbij,vj->nbvi", m[:, :, :3, :3], rest) + m[:, :, None, :3, 3]
    recon = np.einsum("bv,nbvi->nvi", weights, posed)
    np.savez(dst, weights=weights, transforms=m, reconstruction=recon, rmse=float(db.rmse()),
             seconds=seconds, cpu_seconds=cpu, bones=B, version=str(py_dem_bones.__version__),
             rss_kb=_peak_rss_kb())


def _peak_rss_kb():
    """VmHWM (reset by exec; ru_maxrss would carry the parent's high-water mark over from the fork)."""
    try:
        with open("/proc/self/status") as f:
            return float(next(ln.split()[1] for ln in f if ln.startswith("VmHWM:")))
    except (OSError, StopIteration):
        return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
