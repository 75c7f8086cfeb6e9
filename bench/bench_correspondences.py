"""Tracking correspondences on MakeHuman's own 4-view scans: time per stage.

Tracking correspondences (solver.track.correspondences) of the 13,380-vertex MakeHuman subject's exact
posed model against its own unregistered 4-view scans (sample_scenes.unregistered), per stage:

* visibility alone (4 z-buffers) at 320x240 and 640x480, full and half resolution;
* the whole call on a 4 x 320x240 scan (~20k points) and a 4 x 640x480 scan with denser grids
  (~80k points) merged with a second one (~150k points), with and without surface points;
* a point cloud (the same scan without triangles: kNN stand-in triangles for trimming).

Prints the best of ``--repeats`` wall times (the machine is shared) and the median distances.

Usage: ./run bench correspondences [--repeats 3]
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402


def _scan(model, faces, resolution, seed):
    from articula.sample_scenes import unregistered as unreg
    rig = unreg.ScanRig(resolution=resolution, resolution_scale=(1.0, 1.0))
    points, tris, _, _, cams = unreg.scan_frame(model, faces, np.random.default_rng([seed, 1]), rig)
    return points, tris, cams


def _bench_visibility(model, normals, faces, cams, repeats):
    from articula.solver.track.visibility import visible_vertices
    for scale in (1.0, 0.5):
        dt, seen = _common.best_time(lambda: visible_vertices(model, normals, faces, cams, scale), repeats)
        w, h = cams[0][1].width, cams[0][1].height
        _common.report(f"visibility 4 cameras {w}x{h} scale {scale}", dt * 1000, "ms",
                       f"{seen.sum()} of {len(model)} vertices visible")


def _bench_call(label, model, normals, faces, points, pnormals, tris, cams, repeats, **options):
    from articula.solver.track import correspondences as corr
    opts = corr.CorrespondenceOptions(**options)
    dt, out = _common.best_time(
        lambda: corr.correspondences(model, faces, normals, points, pnormals, tris, cams, opts), repeats)
    cap = out.from_capture
    stages = ", ".join(f"{k} {v * 1000:.0f}" for k, v in out.stats["seconds"].items())
    _common.report(f"{label}: {len(points)} points", dt * 1000, "ms",
                   f"stages ms: {stages}; median capture pair {np.median(out.distances[cap]) * 1000:.2f} mm, "
                   f"model pair {np.median(out.distances[~cap]) * 1000:.2f} mm; removed "
                   f"{out.stats['removed_capture']:.0%} / {out.stats['removed_model']:.0%}; "
                   f"{out.stats['rounds']} trimming rounds")


def main(argv=()) -> int:
    parser = argparse.ArgumentParser(prog="bench correspondences")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(list(argv))
    from articula.sample_scenes import registered
    from articula.solver.geometry.normals import vertex_normals
    frames, faces, _ = registered.posed_sequence(n_poses=2, motion="rom", seed=1)
    model = frames[1]
    normals = vertex_normals(model, faces)
    for resolution in ((320, 240), (640, 480)):
        points, tris, cams = _scan(model, faces, resolution, 0)
        _bench_visibility(model, normals, faces, cams, args.repeats)
        if resolution == (640, 480):
            more, more_tris, _ = _scan(model, faces, resolution, 1)
            points, tris = np.concatenate([points, more]), np.concatenate([tris, more_tris + len(points)])
        pnormals = vertex_normals(points, tris)
        for surface in (True, False):
            _bench_call(f"mesh {resolution[0]}x{resolution[1]} surface={surface}", model, normals, faces,
                        points, pnormals, tris, cams, args.repeats, surface=surface)
        _bench_call(f"point cloud {resolution[0]}x{resolution[1]}", model, normals, faces, points, pnormals,
                    None, cams, args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
