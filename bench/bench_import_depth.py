"""Importing a depth recording (articula.import_depth): 300 frames at 640x480 by default.

The recording is synthetic and exact (analytic ray casting, Kinect v1 nominal intrinsics): a floor seen
by a camera 1.2 m high looking slightly down, a back wall at 3.6 m and a 0.45 x 0.35 x 1.7 m "subject"
box walking across, plus 1 mm Gaussian depth noise, written as 16-bit millimetre PNGs by solver.formats.png16
(Up filter).  Import settings: background subtraction (median of the first 10 frames), floor removal,
normals, voxel 0.01 m (``--voxel``).

Printed: the whole operator run (wall clock and CPU time of the process, synchronous as in scripts) and
its split, measured inside the operator: set-up, the frame loop (decode + processing, in worker
threads; the per-stage figures are summed over the threads), cache write, Blender objects; then the cost of one frame change (frame_change_pre handler, points written to
the mesh) and the cache size.

Usage: ./run bench import_depth [--frames 300] [--voxel 0.01] [--keep DIR]
(the recording is generated once, ~1 min, into $ARTICULA_HOME/bench/depth_<frames>, and reused)
   or  ~/.cache/articula/venv-bpy52/bin/python bench/bench_import_depth.py
"""
import argparse
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402


def _addon():
    import bpy
    if not hasattr(bpy.types, "ARTICULA_OT_import_depth"):   # run directly, not through ./run
        sys.path.insert(0, _common.REPO)
        import batch
        batch.enable_addon(bpy)
    return bpy


def write_recording(folder, frames, seed=0):
    """Synthetic 640x480 recording; returns seconds spent."""
    from articula.solver.depth import camera
    from articula.solver.formats.png16 import write_png16
    from articula.sample_scenes.depth_scene import floor_box_scene, ray_box, rays_world
    intr = camera.PRESETS["kinect_v1"]
    rng = np.random.default_rng(seed)
    t = time.perf_counter()
    eye, target = (0.0, 0.0, 1.2), (0.0, 3.0, 0.8)
    static, c2w, _ = floor_box_scene(intr, eye=eye, target=target, box=None, wall_y=3.6)
    static = np.where(static > 0, static, np.inf)
    d = rays_world(intr, c2w)
    for k in range(frames):
        x = 1.2 * np.sin(2 * np.pi * k / max(frames, 1))
        depth = np.minimum(static, ray_box(np.asarray(eye), d, (x - .22, 2.3, 0), (x + .23, 2.65, 1.7)))
        depth = np.where(np.isfinite(depth), depth + rng.normal(scale=0.001, size=depth.shape), 0)
        write_png16(os.path.join(folder, f"depth_{k:04d}.png"), np.round(depth * 1000).astype(np.uint16))
    camera.save_intrinsics(os.path.join(folder, "intrinsics.json"), intr)
    return time.perf_counter() - t


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench import_depth")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--voxel", type=float, default=0.01)
    ap.add_argument("--keep", help="recording folder (default $ARTICULA_HOME/bench/depth_<frames>, written "
                                   "once and reused)")
    args = ap.parse_args(argv)
    bpy = _addon()
    tmp = tempfile.mkdtemp(prefix="articula_bench_depth_")
    home = os.environ.get("ARTICULA_HOME", os.path.join(os.path.expanduser("~"), ".cache", "articula"))
    folder = args.keep or os.path.join(home, "bench", f"depth_{args.frames}")
    os.makedirs(folder, exist_ok=True)
    try:
        if not os.path.exists(os.path.join(folder, f"depth_{args.frames - 1:04d}.png")):
            gen = write_recording(folder, args.frames)
            _common.report("generate recording (not part of the import)", gen, "s", f"{args.frames} frames 640x480")
        bpy.ops.wm.read_homefile(use_empty=True)
        cache = os.path.join(tmp, "points.npz")
        t, c = time.perf_counter(), time.process_time()
        bpy.ops.articula.import_depth(directory=folder, subtract_background=True, voxel_size=args.voxel,
                                      cache_file=cache)
        total, cpu = time.perf_counter() - t, time.process_time() - c
        op_module = sys.modules[bpy.types.ARTICULA_OT_import_depth.__module__]
        tm = dict(op_module.LAST_TIMINGS)
        ob = bpy.context.view_layer.objects.active
        seq = sys.modules[op_module.__name__.rsplit(".", 2)[0] + ".addon.sequences.points"].load_sequence(cache)
        sizes = np.diff(seq.offsets)
        n = args.frames
        _common.report("import_depth operator, total", total, "s", f"{n} frames 640x480, target < 10 s; "
                       f"CPU time {cpu:.2f} s (wall time grows when other processes share the cores)")
        w = tm["workers"]
        _common.report("  set-up: background median, floor fit (wall)", tm["setup"], "s")
        _common.report("  frames: decode + processing (wall)", tm["frames"], "s",
                       f"{1000 * tm['frames'] / n:.1f} ms/frame, {w} worker thread(s)")
        _common.report("    decode (PNG)", tm["decode"], "s", f"summed over the threads; {1000 * tm['decode'] / n:.1f} ms/frame")
        _common.report("    processing", tm["processing"], "s",
                       f"summed over the threads; {1000 * tm['processing'] / n:.1f} ms/frame; "
                       f"range clip, background, floor, normals, voxel {args.voxel} m")
        _common.report("  concatenate", tm["concatenate"], "s")
        _common.report("  cache write", tm["cache"], "s", f"{os.path.getsize(cache) / 1e6:.1f} MB, {len(seq.points)} points")
        _common.report("  Blender objects + first frame", tm["blender"], "s")
        _common.report("  rest (prepare: listing, intrinsics; operator overhead)",
                       total - tm["solver"] - tm["cache"] - tm["blender"], "s")
        _common.report("points per frame", f"{sizes.min()}-{sizes.max()}", "", "; ".join(seq.notes))
        scene = bpy.context.scene
        t = time.perf_counter()
        n = 0
        for f in range(scene.frame_start, min(scene.frame_end, scene.frame_start + 99) + 1):
            scene.frame_set(f)
            n += 1
        _common.report("frame change (frame_set, points rewritten)", 1000 * (time.perf_counter() - t) / n, "ms",
                       f"mean over {n} frames of ~{int(sizes.mean())} points")
        assert ob.articula.frame_count == args.frames
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
