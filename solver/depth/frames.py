"""Depth frames -> per-frame point sets: range clip, background subtraction, floor removal, voxel
downsampling, normals.  Pure numpy/scipy; the recording-wide steps are in ``recording.py``, the Blender
half in ``addon/sequences/points.py``.  The steps are the preprocessing of the depth-camera tracking
dissertation (ch. 4 depth thresholds, ch. 5 ground-plane and background removal; docs/import_depth.md).

Conventions
-----------
* Depth-camera coordinates (the "sensor frame"): x right, y down, z forward (along the optical axis),
  metres, origin at the optical centre.  Pixel (u, v) = (column, row) with integer values at pixel
  *centres*; a pixel with depth z back-projects to ``((u - cx) z / fx, (v - cy) z / fy, z)``.
* Depth images hold raw integers (16-bit PNG, usually millimetres); ``depth_m = raw * depth_scale``.
  0 (and anything outside ``[depth_min, depth_max]``) means "no measurement".
* A plane is ``(n, d)`` with unit normal ``n`` and ``n . p + d = 0``; it is oriented so that the camera
  origin lies on its positive side (``d > 0``), i.e. ``n`` points from the floor up towards the camera.
* "Up" hint for the floor: the camera is assumed roughly upright, so the floor normal is within
  ``floor_max_tilt`` degrees of the sensor's up direction ``(0, -1, 0)``.  A camera looking down by up to
  that angle is fine; a camera on its side is not (then switch floor removal off).

Everything returns float32 point arrays of shape (K, 3) in the sensor frame.  The world placement
(``world_from_sensor``) is computed from the floor plane when one was found.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..errors import ArticulaInputError

SENSOR_UP = np.array([0.0, -1.0, 0.0])


# --------------------------------------------------------------------------------------- options

@dataclasses.dataclass
class DepthOptions:
    """Processing settings; lengths in metres."""
    depth_scale: float = 0.001          # raw integer -> metres (0.001 for millimetre PNGs)
    depth_min: float = 0.3
    depth_max: float = 5.0
    remove_floor: bool = True
    floor_tolerance: float = 0.02       # points closer than this (+ the noise term) to the floor, or below it,
                                        # are removed
    floor_max_tilt: float = 60.0        # degrees between the floor normal and the sensor's up axis
    floor_iterations: int = 256         # RANSAC hypotheses
    floor_min_fraction: float = 0.05    # the floor must hold at least this share of the pooled points
    subtract_background: bool = False
    background_frames: int = 10         # frames (spread over the recording) for the median background
    background_tolerance: float = 0.05  # pixels not at least this (+ the noise term) in front of the background
                                        # are removed
    depth_noise: float = 0.01           # 1/m: depth noise grows ~ z^2 (structured light, ToF); tolerances grow by
                                        # depth_noise * z^2 along the ray (+1 cm at 1 m, +16 cm at 4 m)
    voxel_size: float = 0.0             # 0 = keep every point
    estimate_normals: bool = True
    seed: int = 0
    workers: int = 0                    # threads for decoding/processing frames (0 = min(4, CPU count))

    def validate(self) -> None:
        if not (self.depth_scale > 0 and math.isfinite(self.depth_scale)):
            raise ArticulaInputError(f"depth scale must be a positive number, got {self.depth_scale}")
        if not (0 <= self.depth_min < self.depth_max):
            raise ArticulaInputError(f"depth range [{self.depth_min}, {self.depth_max}] m is empty or negative")
        if self.voxel_size < 0:
            raise ArticulaInputError(f"voxel size must be >= 0, got {self.voxel_size}")
        if self.floor_tolerance <= 0 or self.background_tolerance <= 0 or self.depth_noise < 0:
            raise ArticulaInputError("floor and background tolerances must be positive")
        if self.background_frames < 1:
            raise ArticulaInputError("background needs at least one frame")


# ------------------------------------------------------------------------------- back-projection

def pixel_rays(intr) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ray slopes ``((u - cx) / fx, (v - cy) / fy)``, each (H, W) float32."""
    u = (np.arange(intr.width, dtype=np.float64) - intr.cx) / intr.fx
    v = (np.arange(intr.height, dtype=np.float64) - intr.cy) / intr.fy
    return (np.broadcast_to(u[None, :], (intr.height, intr.width)).astype(np.float32),
            np.broadcast_to(v[:, None], (intr.height, intr.width)).astype(np.float32))


def backproject_grid(depth_m: np.ndarray, rays) -> np.ndarray:
    """(H, W) depth in metres (NaN = invalid) -> (H, W, 3) float32 sensor-frame points (NaN where invalid)."""
    z = depth_m.astype(np.float32, copy=False)
    return np.stack((rays[0] * z, rays[1] * z, z), axis=-1)


def depth_in_metres(raw: np.ndarray, opts: DepthOptions) -> np.ndarray:
    """Raw depth -> metres as float32 with NaN outside ``[depth_min, depth_max]`` (and where raw is 0)."""
    z = raw.astype(np.float32) * np.float32(opts.depth_scale)
    bad = ~((z >= opts.depth_min) & (z <= opts.depth_max))  # also catches NaN
    z[bad] = np.nan
    return z


# ----------------------------------------------------------------------------------- background

def median_background(depths_m) -> np.ndarray:
    """Per-pixel median of valid depths over frames ((F, H, W) or a list of (H, W)); NaN where never
    valid.  (One sort along the frame axis, NaN last; the same values as ``np.nanmedian``, faster.)"""
    stack = np.asarray(depths_m, dtype=np.float32)
    if stack.ndim == 2:
        return stack.copy()
    s = np.sort(stack, axis=0)                      # NaN sort to the end
    n = np.isfinite(stack).sum(axis=0)
    lo = np.maximum((n - 1) // 2, 0)
    hi = np.maximum(n // 2, 0)
    a = np.take_along_axis(s, lo[None], axis=0)[0]
    b = np.take_along_axis(s, hi[None], axis=0)[0]
    med = (a + b) * np.float32(0.5)
    med[n == 0] = np.nan
    return med


def foreground_mask(depth_m: np.ndarray, background_m: np.ndarray, tolerance: float,
                    noise: float = 0.0) -> np.ndarray:
    """True where a pixel is valid and at least ``tolerance + noise * b^2`` in front of the
    background depth ``b`` (the sensor's depth noise grows with the square of the distance).

    Pixels whose background is unknown (NaN) count as foreground when valid.
    """
    valid = np.isfinite(depth_m)
    with np.errstate(invalid="ignore"):
        margin = tolerance + noise * background_m * background_m if noise else tolerance
        in_front = depth_m < background_m - margin
    return valid & (in_front | ~np.isfinite(background_m))


# ---------------------------------------------------------------------------------------- planes

def fit_plane_lsq(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through (N >= 3, 3) points (total least squares via SVD), oriented d >= 0."""
    p = np.asarray(points, dtype=np.float64)
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c, full_matrices=False)
    n = vt[-1]
    d = -float(n @ c)
    if d < 0:
        n, d = -n, -d
    return n, d


def plane_distance(points: np.ndarray, plane) -> np.ndarray:
    """Signed distance of (..., 3) points to ``plane = (n, d)``; positive on the camera side."""
    n, d = plane
    return points @ np.asarray(n, dtype=points.dtype) + points.dtype.type(d)


def ransac_plane(points: np.ndarray, tolerance: float, iterations: int = 256, seed: int = 0,
                 up=SENSOR_UP, max_tilt_deg: float | None = 60.0, sample: int = 4000,
                 refine_steps: int = 3):
    """Robust plane fit: vectorised RANSAC on a random subsample, then least-squares refinement on
    the inliers of all points.

    points (N, 3).  All ``iterations`` hypotheses (random triples) are scored at once against up to
    ``sample`` points.  With ``max_tilt_deg`` only planes whose (camera-facing) normal is within that
    angle of ``up`` are considered.  Deterministic for a given ``seed``.
    Returns ``((n, d), inlier_mask)`` or ``(None, None)`` when no admissible plane exists.
    """
    pts = np.asarray(points, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    n_all = len(pts)
    if n_all < 3:
        return None, None
    rng = np.random.default_rng(seed)
    sub = pts[rng.choice(n_all, size=min(sample, n_all), replace=False)]
    tri = rng.integers(0, len(sub), size=(iterations, 3))
    a, b, c = sub[tri[:, 0]], sub[tri[:, 1]], sub[tri[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n[ok] /= norm[ok, None]
    d = -np.einsum("ij,ij->i", n, a)
    flip = d < 0
    n[flip] *= -1
    d[flip] *= -1
    if max_tilt_deg is not None:
        ok &= n @ np.asarray(up, dtype=np.float64) >= math.cos(math.radians(max_tilt_deg))
    if not ok.any():
        return None, None
    n, d = n[ok], d[ok]
    counts = (np.abs(sub @ n.T + d) < tolerance).sum(axis=0)
    best = int(np.argmax(counts))
    plane = (n[best], float(d[best]))
    inliers = np.abs(plane_distance(pts, plane)) < tolerance
    for _ in range(refine_steps):
        if inliers.sum() < 3:
            break
        plane = fit_plane_lsq(pts[inliers])
        inliers = np.abs(plane_distance(pts, plane)) < tolerance
    if max_tilt_deg is not None and plane[0] @ np.asarray(up, float) < math.cos(math.radians(max_tilt_deg)):
        return None, None
    mask = np.zeros(len(points), dtype=bool)
    finite = np.isfinite(np.asarray(points)).all(axis=1)
    mask[np.flatnonzero(finite)[inliers]] = True
    return plane, mask


def above_floor(points: np.ndarray, floor, tolerance: float, noise: float = 0.0) -> np.ndarray:
    """True for (..., 3) sensor-frame points more than ``tolerance`` above the floor plane, the
    tolerance growing with the depth noise: a depth error ``noise z^2`` along the ray moves a point by
    ``noise z |n . p|`` off the plane (small at grazing angles, where floors are usually seen)."""
    n = np.asarray(floor[0], dtype=points.dtype)
    along = points @ n
    with np.errstate(invalid="ignore"):
        margin = tolerance + noise * points[..., 2] * np.abs(along) if noise else tolerance
        return along + points.dtype.type(floor[1]) >= margin


def world_from_sensor(floor=None) -> np.ndarray:
    """4x4 transform from sensor coordinates (x right, y down, z forward) to the world (Z up).

    With a floor plane ``(n, d)``: world +Z = floor normal, the origin is the floor point right below
    the camera (so the camera sits at height ``d`` on the world Z axis), world +Y = the optical axis
    projected onto the floor, +X = Y x Z (the camera's right).  Without a floor: the camera is at the
    origin looking along world +Y, sensor x -> world X, sensor y (down) -> world -Z.
    """
    m = np.eye(4)
    if floor is None:
        m[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
        return m
    n, d = np.asarray(floor[0], float), float(floor[1])
    fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
    if np.linalg.norm(fwd) < 1e-6:  # looking straight down: use the sensor's up as forward
        fwd = SENSOR_UP - (SENSOR_UP @ n) * n
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, n)
    rot = np.stack((right, fwd, n))  # rows: world axes expressed in sensor coordinates
    origin = -d * n                  # foot of the camera on the floor, sensor coordinates
    m[:3, :3] = rot
    m[:3, 3] = -rot @ origin
    return m


# --------------------------------------------------------------------------------------- normals

def grid_normals(grid: np.ndarray, rows=None, cols=None, jump: float = 0.01, mask=None) -> np.ndarray:
    """Normals of a back-projected depth grid (H, W, 3) (NaN = invalid) from pixel neighbours.

    Along each image axis the tangent is the central difference when both neighbours are valid and
    their depth steps are alike (``max <= 2 min + jump`` metres); otherwise the one-sided difference with
    the smaller depth step, so normals next to depth discontinuities come from the same surface.
    Normals face the camera (``n . p < 0``); where no neighbour exists the normal is the reversed
    viewing ray.  With ``rows, cols`` (K,) only those pixels are computed (gathers, no full-image
    temporaries) and (K, 3) is returned; otherwise (H, W, 3).  ``mask`` (H, W): pixels outside it count
    as invalid neighbours.  float32.
    """
    g = grid.astype(np.float32, copy=False)
    h, w = g.shape[:2]
    full = rows is None
    if full:
        rows, cols = np.nonzero(np.ones((h, w), bool))
    rows, cols = np.asarray(rows), np.asarray(cols)
    if len(rows) == 0:
        return np.zeros((h, w, 3) if full else (0, 3), np.float32)
    # work on the bounding box of the requested pixels (plus their neighbours), padded with NaN
    r0, r1 = max(int(rows.min()) - 1, 0), min(int(rows.max()) + 2, h)
    c0, c1 = max(int(cols.min()) - 1, 0), min(int(cols.max()) + 2, w)
    padded = np.full((r1 - r0 + 2, c1 - c0 + 2, 3), np.nan, np.float32)
    if mask is None:
        padded[1:-1, 1:-1] = g[r0:r1, c0:c1]
    else:
        np.copyto(padded[1:-1, 1:-1], g[r0:r1, c0:c1], where=mask[r0:r1, c0:c1, None])
    r, c = rows - r0 + 1, cols - c0 + 1
    p = padded[r, c]

    def tangent(dr, dc):
        fwd = padded[r + dr, c + dc] - p
        bwd = p - padded[r - dr, c - dc]
        jf = np.abs(fwd[:, 2])
        jb = np.abs(bwd[:, 2])
        jf = np.where(np.isfinite(jf), jf, np.inf)
        jb = np.where(np.isfinite(jb), jb, np.inf)
        lo, hi = np.minimum(jf, jb), np.maximum(jf, jb)
        central = np.isfinite(hi) & (hi <= 2 * lo + jump)
        one_sided = np.where((jf <= jb)[:, None], fwd, bwd)
        return np.where(central[:, None], 0.5 * (fwd + bwd), one_sided)

    tu, tv = tangent(0, 1), tangent(1, 0)
    n = np.empty_like(tu)
    n[:, 0] = tu[:, 1] * tv[:, 2] - tu[:, 2] * tv[:, 1]
    n[:, 1] = tu[:, 2] * tv[:, 0] - tu[:, 0] * tv[:, 2]
    n[:, 2] = tu[:, 0] * tv[:, 1] - tu[:, 1] * tv[:, 0]
    length = np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / length
        ray = -p / np.sqrt(np.einsum("ij,ij->i", p, p))[:, None]
    bad = ~(np.isfinite(n).all(axis=1) & (length[:, 0] > 0))
    n[bad] = ray[bad]
    flip = np.einsum("ij,ij->i", n, p) > 0
    n[flip] *= -1
    n = n.astype(np.float32)
    return n.reshape(h, w, 3) if full else n


def pca_normals(points: np.ndarray, k: int = 12, viewpoint=(0.0, 0.0, 0.0), away_from=None) -> np.ndarray:
    """Normals of an unorganised (N, 3) cloud: smallest principal axis of the k nearest neighbours
    (scipy cKDTree), oriented towards ``viewpoint`` (the sensor origin), or away from the point
    ``away_from`` when it is given (a cloud whose sensor is unknown, e.g. away from its centroid).
    Returns (N, 3) float32."""
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    if len(p) < 3:
        out = np.asarray(viewpoint, float) - p if away_from is None else p - np.asarray(away_from, float)
        return (out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)).astype(np.float32)
    k = min(k, len(p))
    _, idx = cKDTree(p).query(p, k=k)
    nb = p[idx] - p[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vecs = np.linalg.eigh(cov)
    n = vecs[:, :, 0]
    towards = np.asarray(viewpoint, float) - p if away_from is None else p - np.asarray(away_from, float)
    flip = np.einsum("ij,ij->i", n, towards) < 0
    n[flip] *= -1
    return n.astype(np.float32)


# ---------------------------------------------------------------------------------- downsampling

def voxel_groups(points: np.ndarray, voxel: float):
    """``(group (N,) intp, m)``: the index of every point's cubic voxel of edge ``voxel`` among the ``m``
    occupied ones, voxels ordered by their key.  Keys are ``floor(p / voxel)`` packed into one int64,
    grouped with one sort.  points (N, 3), N > 0."""
    q = np.floor(np.asarray(points) / voxel).astype(np.int64)
    q -= q.min(axis=0)
    dims = q.max(axis=0) + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) >= 2.0 ** 62:
        raise ArticulaInputError(f"voxel size {voxel} m is too small for a cloud this large")
    key = (q[:, 0] * dims[1] + q[:, 1]) * dims[2] + q[:, 2]
    order = np.argsort(key)
    ks = key[order]
    first = np.empty(len(ks), bool)
    first[0] = True
    np.not_equal(ks[1:], ks[:-1], out=first[1:])
    group = np.empty(len(ks), np.intp)
    group[order] = np.cumsum(first) - 1          # voxel index of every point, in key order
    return group, int(group.max()) + 1


def voxel_downsample(points: np.ndarray, voxel: float, *attributes):
    """Average points (and per-point attributes) per cubic voxel of edge ``voxel``.

    points (N, 3); each attribute (N, C).  Voxels of :func:`voxel_groups`; the sums are ``np.bincount``
    with weights.  Returns ``(points, *attributes)`` with one row per occupied voxel,
    ordered by key (deterministic).  Attributes named normals should be re-normalised by the caller.
    """
    p = np.asarray(points)
    if voxel <= 0 or len(p) == 0:
        return (p, *attributes)
    group, m = voxel_groups(p, voxel)
    counts = np.bincount(group, minlength=m).astype(np.float64)

    def mean(a):
        a = np.asarray(a)
        cols = [np.bincount(group, weights=a[:, j], minlength=m) for j in range(a.shape[1])]
        return (np.stack(cols, axis=1) / counts[:, None]).astype(a.dtype)

    return (mean(p), *(mean(a) for a in attributes))


def normalize_rows(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return (v / np.maximum(length, 1e-12)).astype(v.dtype)


# ------------------------------------------------------------------------------------ one frame

@dataclasses.dataclass
class FramePoints:
    """Points of one frame, sensor frame.  ``pixels`` (K, 2) float32 (u, v) of each point's pixel
    (the mean pixel after voxel downsampling), or None for point-cloud files."""
    points: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    pixels: np.ndarray | None = None


def frame_mask(depth_m: np.ndarray, grid: np.ndarray, opts: DepthOptions, background=None, floor=None):
    """Which pixels survive range clip (NaN already), background subtraction and floor removal."""
    keep = np.isfinite(depth_m)
    if background is not None:
        keep &= foreground_mask(depth_m, background, opts.background_tolerance, opts.depth_noise)
    if floor is not None:
        keep &= above_floor(grid, floor, opts.floor_tolerance, opts.depth_noise)
    return keep


def process_depth(depth_m: np.ndarray, rays, opts: DepthOptions, background=None, floor=None,
                  color=None) -> FramePoints:
    """One depth frame (metres, NaN invalid) -> the points that survive the filters.

    ``color``: optional (Hc, Wc, 3) image (float 0..1 or uint8) registered to the depth image (the colour of depth
    pixel (u, v) is the nearest colour pixel at ``(u * Wc / W, v * Hc / H)``).
    """
    grid = backproject_grid(depth_m, rays)
    keep = frame_mask(depth_m, grid, opts, background, floor)
    rows, cols = np.nonzero(keep)
    pts = grid[rows, cols]
    attrs = {"pixels": np.stack((cols, rows), axis=1).astype(np.float32)}
    if opts.estimate_normals:
        attrs["normals"] = grid_normals(grid, rows, cols, mask=keep)
    if color is not None:
        hc, wc = color.shape[:2]
        h, w = depth_m.shape
        ci = np.minimum(((rows + 0.5) * hc / h).astype(np.intp), hc - 1)
        cj = np.minimum(((cols + 0.5) * wc / w).astype(np.intp), wc - 1)
        c = color[ci, cj, :3]
        attrs["colors"] = c.astype(np.float32) / 255 if c.dtype == np.uint8 else c.astype(np.float32)
    if opts.voxel_size > 0:
        names = list(attrs)
        pts, *vals = voxel_downsample(pts, opts.voxel_size, *(attrs[n] for n in names))
        attrs = dict(zip(names, vals))
        if "normals" in attrs:
            attrs["normals"] = normalize_rows(attrs["normals"])
    return FramePoints(pts.astype(np.float32), attrs.get("normals"), attrs.get("colors"), attrs["pixels"])


def process_cloud(points: np.ndarray, opts: DepthOptions, floor=None, colors=None) -> FramePoints:
    """One point-cloud frame (sensor frame) -> range clip (on z), floor removal, voxels, PCA normals."""
    p = np.asarray(points, dtype=np.float32)
    keep = (p[:, 2] >= opts.depth_min) & (p[:, 2] <= opts.depth_max)
    if floor is not None:
        keep &= above_floor(p, floor, opts.floor_tolerance, opts.depth_noise)
    p = p[keep]
    c = None if colors is None else np.asarray(colors, np.float32)[keep]
    if opts.voxel_size > 0:
        if c is None:
            (p,) = voxel_downsample(p, opts.voxel_size)
        else:
            p, c = voxel_downsample(p, opts.voxel_size, c)
    n = pca_normals(p) if opts.estimate_normals else None
    return FramePoints(p.astype(np.float32), n, c)
