"""Progress of rig learning on a 53,514-vertex mesh: the longest gaps between progress calls.

Progress reporting of rig learning on a large mesh: the longest gaps between two progress calls of
``solver.learn.pipeline.learn_rig`` (default options) on the MakeHuman subject (cmu_mb, hybrid skin, 5 poses)
subdivided once by edge midpoints (53,514 vertices), and whether the fractions never decrease.

Usage: ./run bench learn_progress [--poses 5] [--gaps 8]
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402


def subdivide(frames, faces):
    """Midpoint subdivision of triangles: every edge gets its midpoint, each triangle becomes four.
    ``frames (M, V, 3)``, ``faces (F, 3)`` -> ``(M, V + E, 3)``, ``(4F, 3)``."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    m01, m12, m20 = frames.shape[1] + inv.ravel().reshape(3, len(faces))
    a, b, c = faces.T
    new_faces = np.concatenate([np.stack([a, m01, m20], 1), np.stack([m01, b, m12], 1),
                                np.stack([m20, m12, c], 1), np.stack([m01, m12, m20], 1)]).astype(np.int32)
    mids = 0.5 * (frames[:, uniq[:, 0]] + frames[:, uniq[:, 1]])
    return np.concatenate([frames, mids], axis=1), new_faces


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench learn_progress")
    p.add_argument("--poses", type=int, default=5)
    p.add_argument("--gaps", type=int, default=8, help="how many of the longest gaps to print")
    args = p.parse_args(argv)
    from articula.sample_scenes import registered
    from articula.solver.learn import pipeline
    frames, faces, _ = registered.posed_sequence(rig="cmu_mb", n_poses=args.poses, skin="hybrid")
    frames, faces = subdivide(np.asarray(frames), np.asarray(faces))
    calls = [(time.perf_counter(), 0.0, "start")]
    result = pipeline.learn_rig(frames, faces, progress=lambda f, stage, obj=None:
                                calls.append((time.perf_counter(), float(f), stage)))
    calls.append((time.perf_counter(), 1.0, "end"))
    gaps = sorted(((b[0] - a[0], a[2], b[2]) for a, b in zip(calls, calls[1:])), reverse=True)
    print(f"MakeHuman cmu_mb subdivided: {frames.shape[1]} vertices x {len(frames)} scans, "
          f"{result.report.get('parts')} parts")
    _common.report("learning wall time", calls[-1][0] - calls[0][0], "s")
    _common.report("progress calls", len(calls) - 2)
    for g, a, b in gaps[:args.gaps]:
        _common.report("gap", g, "s", f"after {a!r} until {b!r}")
    fractions = [c[1] for c in calls]
    _common.report("fractions non-decreasing", all(x <= y + 1e-12 for x, y in zip(fractions, fractions[1:])))
    print("timings_s", json.dumps({k: round(v, 1) for k, v in result.report["timings_s"].items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
