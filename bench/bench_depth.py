"""Synthetic depth recordings and the 16-bit PNG codec.

* ``samples depth`` work: 60 frames of the 13,380-vertex MakeHuman subject at 320x240 and 640x480
  (posing excluded; rendering + noise + PNG writing), with a per-stage split at 640x480;
* PNG decoding of 300 frames at 640x480 (one by one and batched with ``read_png16_many``): our
  own files (Up filter), the real Kinect v1 frames of
  ``../shared/data/depth/skeltrack_kinect`` (libpng, mixed Sub/Up/Paeth rows; skipped if absent), and
  an all-Paeth file (worst case: the wavefront unfilter on every row).

Usage: ./run bench depth [--frames 60] [--decodes 300]
"""
import argparse
import glob
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

_CHECKOUT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
KINECT_DIR = os.path.join(os.path.dirname(_CHECKOUT), "shared", "data", "depth", "skeltrack_kinect")


def _bench_generate(frames, faces, gt, n, tmp):
    from articula.sample_scenes.depth_recording import generate_depth
    for res in ((320, 240), (640, 480)):
        t0, c0 = time.perf_counter(), time.process_time()
        generate_depth(os.path.join(tmp, f"rec{res[0]}"), frames[:n], faces, gt, resolution=res, seed=0)
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        _common.report(f"generate {n} frames {res[0]}x{res[1]}", dt, "s wall",
                       f"{dt / n * 1000:.1f} ms/frame wall, CPU {cpu:.2f} s")


def _bench_stages(frames, faces, tmp):
    from articula.sample_scenes import depth_recording as rec
    from articula.sample_scenes.depth_noise import NoiseParams, apply_noise
    from articula.sample_scenes.depth_render import incidence_cosine, render_depth
    from articula.solver.depth import camera
    from articula.solver.formats.png16 import write_png16
    intr = camera.preset("kinect_v1")
    lo, hi = frames.reshape(-1, 3).min(0), frames.reshape(-1, 3).max(0)
    centre = (lo + hi) / 2
    sv, sf = rec.scenery(centre, lo[2], True, False)
    c2w = rec.CameraPlacement().cam_to_world(centre, lo[2])
    verts = camera.world_to_camera(np.concatenate([frames[0], sv]), c2w)
    allf = np.concatenate([faces, sf + len(frames[0])])
    times = {}

    def timed(name, fn, reps=5):
        best = min(_timeit(fn) for _ in range(reps))
        times[name] = best
        return fn()
    depth, tri = timed("render", lambda: render_depth(verts, allf, intr))
    cos = timed("incidence", lambda: incidence_cosine(verts, allf, tri, intr))
    noisy = timed("noise", lambda: apply_noise(depth, cos, np.random.default_rng(0), NoiseParams(), intr.fx))
    path = os.path.join(tmp, "one.png")
    timed("png write", lambda: write_png16(path, rec.to_millimetres(noisy)))
    for name, t in times.items():
        _common.report(f"640x480 {name}", t * 1000, "ms/frame CPU", f"best of 5, {len(faces) + len(sf)} triangles")


def _timeit(fn):
    """CPU seconds of one call (the machine may be shared; wall time is reported elsewhere)."""
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def _bench_decode(files, n, label):
    from articula.solver.formats.png16 import read_png16, read_png16_many
    paths = [files[i % len(files)] for i in range(n)]
    for name, fn in (("read_png16", lambda: [read_png16(p) for p in paths]),
                     ("read_png16_many", lambda: read_png16_many(paths))):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        _common.report(f"decode {n} x 640x480 {label}, {name}", dt, "s",
                       f"{dt / n * 1000:.1f} ms/frame wall, {cpu / n * 1000:.1f} ms/frame CPU")


def _rowwise_unfilter(filtered, types):
    """The obvious alternative to the wavefront: row after row, a Python loop over the pixels of
    Average/Paeth rows (vectorised over the bytes of one pixel only).  For timing only."""
    out = np.zeros(filtered.shape, np.int16)
    prior = np.zeros(filtered.shape[1:], np.int16)
    for r, t in enumerate(types):
        row = filtered[r].astype(np.int16)
        cur = out[r]
        for x in range(row.shape[0]):
            a = cur[x - 1] if x else 0 * prior[0]
            b, c = prior[x], (prior[x - 1] if x else 0 * prior[0])
            if t == 3:
                pred = (a + b) >> 1
            elif t == 4:
                pa, pb, pc = np.abs(b - c), np.abs(a - c), np.abs(a + b - 2 * c)
                pred = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
            else:
                pred = (0 * b, a, b)[t]
            cur[x] = (row[x] + pred) & 255
        prior = cur
    return out.astype(np.uint8)


def _bench_alternative(path):
    from articula.solver.formats import png16
    with open(path, "rb") as fh:
        _, filtered, types = png16._inflate(fh.read(), path)
    rows = 24
    c0 = time.process_time()
    slow = _rowwise_unfilter(filtered[:rows], types[:rows])
    cpu = (time.process_time() - c0) * len(types) / rows
    assert np.array_equal(slow, png16.unfilter(filtered[:rows], types[:rows]))
    _common.report("unfilter row by row (per-pixel loop), extrapolated to one frame", cpu * 1000, "ms CPU",
                   f"measured on {rows} rows of {os.path.basename(path)}; same result as the wavefront")


def main(argv) -> int:
    ap = argparse.ArgumentParser(prog="bench depth")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--decodes", type=int, default=300)
    args = ap.parse_args(argv)
    from articula.sample_scenes.registered import posed_sequence
    from articula.solver.formats.png16 import write_png16
    frames, faces, gt = posed_sequence(n_poses=args.frames, seed=0)
    gt = {k: v for k, v in gt.items() if k != "posed_vertices"}
    _common.report("subject", f"{frames.shape[1]} vertices, {len(faces)} triangles")
    with tempfile.TemporaryDirectory() as tmp:
        _bench_generate(frames, faces, gt, args.frames, tmp)
        _bench_stages(frames, faces, tmp)
        own = sorted(glob.glob(os.path.join(tmp, "rec640", "depth_*.png")))
        _bench_decode(own, args.decodes, "own files (Up filter)")
        kinect = sorted(glob.glob(os.path.join(KINECT_DIR, "*.png")))
        if kinect:
            _bench_decode(kinect, args.decodes, "real Kinect v1 files (libpng, Sub/Up/Paeth)")
        else:
            _common.report("decode real Kinect files", "skipped", note=f"{KINECT_DIR} absent")
        from articula.solver.formats.png16 import read_png16
        paeth = os.path.join(tmp, "paeth.png")
        write_png16(paeth, read_png16(own[0]), filter_type="paeth")
        _bench_decode([paeth], max(1, args.decodes // 10), "all-Paeth file (worst case)")
        _bench_alternative(paeth)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
