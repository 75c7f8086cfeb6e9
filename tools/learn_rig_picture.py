"""Draw a learned rig over its rest mesh: ``python tools/learn_rig_picture.py MODEL.npz [MODEL2.npz ...]
OUT.png [--height 420]`` (the pictures of docs/learn_rig.md).  One panel per bundle, side by side: the
rest vertices in grey (nearer brighter), seen along the mesh's thinnest principal axis turned 25° about
its longest; bones as lines from head to tail, left bones (``.L``) red, right (``.R``) blue, the others
yellow; joints outside the mesh (winding number) as magenta squares."""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "bench"))
sys.path.insert(0, HERE)
import _common  # noqa: E402,F401  (makes ``import articula`` work)
from depth_fit_picture import _line, write_rgb  # noqa: E402

COLOURS = {".L": (230, 60, 50), ".R": (60, 110, 240), "": (240, 210, 40)}


def view_axes(points):
    """``(3,3)`` rows u (right), v (up), w (towards the viewer): principal axes, the view along the thinnest
    turned 25° about the longest."""
    c = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(c.T @ c)
    e1, e2, e3 = vecs[:, 2], vecs[:, 1], vecs[:, 0]
    a = np.radians(25.0)
    w = np.cos(a) * e3 + np.sin(a) * e2
    return np.stack([e1, np.cross(w, e1), w])


def panel(model, height):
    """One bundle's picture ``(H, W, 3)`` uint8."""
    from articula.solver.geometry.inside import distance_outside
    rest, sk = model.rest_vertices, model.skeleton
    axes = view_axes(rest)
    p = rest @ axes.T
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    scale = 0.9 * height / max(hi[1] - lo[1], 1e-12)
    width = int((hi[0] - lo[0]) * scale / 0.9) + 1

    def px(x):
        q = (np.atleast_2d(x) @ axes.T)[:, :2]
        return np.c_[(q[:, 0] - lo[0]) * scale + 0.05 * width, height - ((q[:, 1] - lo[1]) * scale + 0.05 * height)]
    img = np.full((height, width, 3), 25, np.uint8)
    uv = np.round(px(rest)).astype(int)
    shade = (70 + 150 * (p[:, 2] - p[:, 2].min()) / max(np.ptp(p[:, 2]), 1e-12)).astype(np.uint8)
    order = np.argsort(p[:, 2])                               # far first, near drawn over it
    ok = (uv[order, 0] >= 0) & (uv[order, 0] < width) & (uv[order, 1] >= 0) & (uv[order, 1] < height)
    o = order[ok]
    for du, dv in ((0, 0), (1, 0), (0, 1), (1, 1)):                 # 2x2 dots
        img[np.minimum(uv[o, 1] + dv, height - 1), np.minimum(uv[o, 0] + du, width - 1)] = shade[o, None]
    heads, tails = px(sk.heads), px(sk.tails)
    for b, name in enumerate(sk.names):
        colour = COLOURS[name[-2:]] if name[-2:] in (".L", ".R") else COLOURS[""]
        _line(img, heads[b], tails[b], colour)
    outside = distance_outside(sk.heads[1:], rest, model.faces) > 0
    for u, v in np.round(heads[1:][outside]).astype(int):
        img[max(v - 3, 0):v + 4, max(u - 3, 0):u + 4] = (230, 40, 230)
    return img


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("bundles", nargs="+")
    ap.add_argument("--height", type=int, default=420)
    args = ap.parse_args(argv)
    from articula.solver.formats.bundle import load_bundle
    *bundles, out = args.bundles
    panels = [panel(load_bundle(path).model, args.height) for path in bundles]
    gap = np.full((args.height, 8, 3), 255, np.uint8)
    write_rgb(out, np.concatenate([x for pnl in panels for x in (pnl, gap)][:-1], axis=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
