"""Peak memory of rig learning against the estimate that ``learn_rig`` refuses by.

    ./run bench learn_memory                                  # the cases of docs/learn_rig_solver.md
    ./run bench learn_memory --case makehuman:30:19 --case subdiv2:5:10

Each case runs in a child process of its own (``--child``): the data are made, the process's peak
resident set (``VmHWM`` of /proc/self/status) is reset to its current size (``/proc/self/clear_refs``
5), ``learn_rig`` runs, and the child prints its RSS before, its peak during the run, and
``pipeline.working_memory_bytes`` for that input.  A case is ``data:scans:parts[:iterations]``; data
``makehuman`` (13,380 v, hybrid skin, rom poses), ``subdiv1`` / ``subdiv2`` (that mesh and scans
midpoint-subdivided once / twice: 53,286 / 212,898 v... as printed), ``bone`` (Dem Bones' Bone_Anim,
754 v; scans = key scans of its 400 frames).  ``iterations`` (default 1) is learn_rig's max_iterations:
the two warm-start rounds and the first round repeat every step, so later rounds add no new peak.
"""
import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

CASES = ("makehuman:30:19", "bone:40:10", "subdiv1:5:5", "subdiv1:5:19", "subdiv1:10:10", "subdiv2:5:10")


def _status_kib(key):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def subdivide(scans, faces):
    """Midpoint subdivision (each triangle -> 4) of ``scans (M,V,3)`` sharing ``faces (F,3)``."""
    V = scans.shape[1]
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, inverse = np.unique(e, axis=0, return_inverse=True)
    inverse = inverse.reshape(3, -1).T + V                     # the new vertex of each face's edges
    mid = 0.5 * (scans[:, edges[:, 0]] + scans[:, edges[:, 1]])
    a, b, c = faces.T
    ab, bc, ca = inverse.T
    new = np.concatenate([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                          np.stack([ab, bc, ca], 1)])
    return np.concatenate([scans, mid], axis=1), new.astype(np.int32)


def case_data(name, scans):
    """``(scans (M,V,3) float64, faces, key_scans option)`` of data ``name``."""
    if name == "bone":
        from _learn_runs import bone_anim
        _, frames, _, tris = bone_anim()
        return frames, np.asarray(tris, np.int32), scans
    from articula.sample_scenes.registered import posed_sequence
    verts, faces, _ = posed_sequence(rig="cmu_mb", shape="female", n_poses=scans, motion="rom", skin="hybrid",
                                     seed=0)
    verts, faces = np.asarray(verts, np.float64), np.asarray(faces, np.int32)
    for _ in range({"makehuman": 0, "subdiv1": 1, "subdiv2": 2}[name]):
        verts, faces = subdivide(verts, faces)
    return verts, faces, 0


def child(spec):
    from articula.solver.learn.memory import working_memory_bytes
    from articula.solver.learn.pipeline import learn_rig
    name, scans, parts, *rest = spec.split(":")
    iterations = int(rest[0]) if rest else 1
    verts, faces, keys = case_data(name, int(scans))
    verts = np.ascontiguousarray(verts)
    with open("/proc/self/clear_refs", "w") as fh:             # VmHWM := VmRSS
        fh.write("5")
    before = _status_kib("VmRSS") * 1024
    t0 = time.perf_counter()
    learn_rig(verts, faces, parts=int(parts), key_scans=keys, max_iterations=iterations)
    peak = _status_kib("VmHWM") * 1024
    M, V = verts.shape[:2]
    learned = min(M, keys) if keys else M
    print(json.dumps(dict(case=spec, scans=M, learned=learned, vertices=V, parts=int(parts), before=before,
                          peak=peak, seconds=time.perf_counter() - t0,
                          estimate=working_memory_bytes(learned, V, int(parts), M))))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench learn_memory")
    ap.add_argument("--case", action="append", help=f"data:scans:parts[:iterations] (default {' '.join(CASES)})")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        return child(args.child)
    for spec in args.case or CASES:
        run = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", spec], capture_output=True,
                             text=True)
        if run.returncode:
            print(run.stderr[-2000:], file=sys.stderr)
            return 1
        r = json.loads(run.stdout.strip().splitlines()[-1])
        delta = r["peak"] - r["before"]
        _common.report(f"{spec} peak during learn_rig", r["peak"] / 1e9, "GB",
                       f"{r['scans']} scans ({r['learned']} learned) x {r['vertices']} v, {r['parts']} parts; "
                       f"RSS before {r['before'] / 1e9:.2f} GB, rise {delta / 1e9:.2f} GB, estimate "
                       f"{r['estimate'] / 1e9:.2f} GB (estimate/peak {r['estimate'] / r['peak']:.2f}); "
                       f"{r['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
