"""Track a depth recording and draw the fit over its depth frames: ``python tools/depth_fit_picture.py
DIR OUT.png [--camera kinect_v1] [--model MODEL.npz] [--frames 0,4,8]`` (the docs' pictures of
docs/track_depth.md).  Each panel: the frame's depth in grey (the person brighter), the tracked model's
visible surface points coloured by depth, its skeleton in yellow."""
import argparse
import os
import struct
import sys
import zlib

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bench"))
import _common  # noqa: E402,F401  (makes ``import articula`` work)


def write_rgb(path, img):
    """(H, W, 3) uint8 -> PNG."""
    h, w = img.shape[:2]
    raw = b"".join(b"\x00" + img[r].tobytes() for r in range(h))

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def _line(img, a, b, color):
    n = int(max(abs(b - a).max(), 1))
    for t in np.linspace(0, 1, n + 1):
        u, v = np.round(a + t * (b - a)).astype(int)
        if 0 <= v < img.shape[0] and 0 <= u < img.shape[1]:
            img[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2] = color


def panel(obs, body, pose, camera):
    """One frame's picture (H, W, 3) uint8."""
    from articula.solver.track_depth.visibility import visible
    z = obs.depth
    img = np.zeros(z.shape + (3,), np.uint8)
    finite = np.isfinite(z)
    img[finite] = 40
    img[obs.mask] = 90
    posed = body.pose(pose)
    vis = visible(posed.points, posed.normals, camera, 0.03)
    uv, depth = camera.project(posed.points[vis])
    lo, hi = np.percentile(depth, [2, 98]) if len(depth) else (0, 1)
    t = np.clip((depth - lo) / max(hi - lo, 1e-6), 0, 1)
    colors = np.stack((255 * (1 - t), 80 + 100 * t, 255 * t), axis=1).astype(np.uint8)
    H, W = z.shape
    for (u, v), c in zip(np.round(uv).astype(int), colors):
        if 0 <= v < H and 0 <= u < W:
            img[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2] = c
    juv, _ = camera.project(posed.joints)
    for b, p in enumerate(body.model.skeleton.parents):
        if p >= 0:
            _line(img, juv[p], juv[b], (255, 230, 0))
    return img


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("folder")
    ap.add_argument("out")
    ap.add_argument("--camera", default=None)
    ap.add_argument("--model", default=None)
    ap.add_argument("--frames", default="")
    ap.add_argument("--columns", type=int, default=4)
    a = ap.parse_args(argv)
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.tracking.blend_body import BlendBody
    from articula.solver.track_depth.pipeline import track_recording
    from articula.solver.track_depth.source import DepthRecording
    rec = DepthRecording.from_folder(a.folder, preset=a.camera)
    model = load_bundle(a.model).model if a.model else None
    res = track_recording(rec, model)
    print(res.report()["per_frame"][:3], res.notes)
    body = BlendBody(res.model, count=4000)
    picks = [int(k) for k in a.frames.split(",")] if a.frames else list(range(len(rec)))
    panels = {}
    for k, obs in rec.observations(2500):
        if k in picks:
            panels[k] = panel(obs, body, res.poses.take(k), rec.camera)
    tiles = [panels[k] for k in picks]
    rows = [np.concatenate(tiles[i:i + a.columns] + [np.zeros_like(tiles[0])] * (a.columns - len(tiles[i:i + a.columns])), axis=1)
            for i in range(0, len(tiles), a.columns)]
    write_rgb(a.out, np.concatenate(rows, axis=0))
    print("wrote", a.out, [f["status"] for f in res.frames])
    return 0


if __name__ == "__main__":
    sys.exit(main())
