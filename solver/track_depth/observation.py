"""One depth frame as the tracker sees it: the person's pixels, their points, normals and silhouette.

Preprocessing (depth-camera tracking dissertation, ch. 2 and 5): range clip, static background and floor
removed (:mod:`solver.depth.frames`), then the person is the largest connected foreground component,
connectivity broken at depth jumps so an object touching the person in the image but standing apart in
depth is not merged.  Points are sampled on the image grid (ch. 6 samples the observation uniformly on
the grid), the silhouette edge pixels keep their 2D contour normals (ch. 5, §4.4 edge term).  Everything
is in the tracking frame (``camera.cam_to_world`` applied).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..depth import frames as dp

JUMP_M = 0.05          # neighbouring pixels further apart in depth than this (+ noise) are not connected
MIN_PERSON_SHARE = 0.004  # a component smaller than this share of the image is nobody
MIN_PERSON_POINTS = 150
MIN_PART_PIXELS = 10      # smaller components near the person are noise, not body parts
FREE_BEHIND_M = 0.1      # a pixel seeing this far behind a model point shows free space there
FLOOR_BAND_M = 0.12       # model points lower than this over the floor may hide in the cut-off floor band
CONTACT_M = 0.02          # see floor_margin
REACH_M = 0.08            # a component this close (3D) to the person's largest one is part of it
PERSON_OF_LARGEST = 0.3   # a component this share of the largest one's size may be a person
PERSON_EXTENT_M = 0.5     # ... when it spans this much in 3D (bounding box diagonal)


@dataclasses.dataclass
class ViewCamera:
    """The depth camera: :class:`~solver.depth.camera.Intrinsics` and ``cam_to_world`` (4, 4) from the
    camera frame (OpenCV axes) to the tracking frame."""
    intr: object
    cam_to_world: np.ndarray

    def __post_init__(self):
        self.cam_to_world = np.asarray(self.cam_to_world, dtype=np.float64)
        self.R = self.cam_to_world[:3, :3]
        self.t = self.cam_to_world[:3, 3]

    @property
    def centre(self) -> np.ndarray:
        return self.t

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        return (points - self.t) @ self.R

    def project(self, points: np.ndarray):
        """(N, 3) tracking-frame points -> pixel (N, 2) (u right, v down) and depth z (N,) metres."""
        c = self.to_camera(points)
        z = c[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack((self.intr.fx * c[:, 0] / z + self.intr.cx, self.intr.fy * c[:, 1] / z + self.intr.cy), 1)
        return uv, z


@dataclasses.dataclass
class Observation:
    """The person in one frame.  ``points`` / ``normals`` (N, 3) tracking frame; ``pixels`` (N, 2);
    ``boundary`` (N,) bool, points on the silhouette (their normals are unreliable, ch. 5 rejects pairs
    with them); ``edge_points`` (E, 3), ``edge_pixels`` (E, 2), ``edge_normals`` (E, 2) the silhouette
    pixels with outward 2D contour normals; ``mask`` (H, W) bool, the person's pixels; ``depth`` (H, W)
    metres (NaN invalid), for the free-space test of hypotheses; ``person_pixels`` the component size;
    ``others`` the other person-sized components in view ``[(pixels, centre (3,) sensor frame)]``;
    ``centre`` (3,) the person's median point in the sensor frame (the next frame keeps to it)."""
    points: np.ndarray
    normals: np.ndarray
    pixels: np.ndarray
    boundary: np.ndarray
    edge_points: np.ndarray
    edge_pixels: np.ndarray
    edge_normals: np.ndarray
    mask: np.ndarray
    depth: np.ndarray
    person_pixels: int
    floor: tuple | None = None
    others: list = dataclasses.field(default_factory=list)
    centre: np.ndarray | None = None

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed height (m) of tracking-frame points above the floor plane (needs ``floor``)."""
        n, d = self.floor
        return points @ n + d

    @property
    def empty(self) -> bool:
        return len(self.points) < MIN_PERSON_POINTS

    def tree(self) -> cKDTree:
        if not hasattr(self, "_tree"):
            self._tree = cKDTree(self.points)
        return self._tree

    def mask_dilated(self, pixels: int = 2) -> np.ndarray:
        """The person's mask grown by ``pixels`` (model points just past the silhouette are not in free space)."""
        if not hasattr(self, "_dilated"):
            self._dilated = ndimage.binary_dilation(self.mask, iterations=pixels)
        return self._dilated

    def in_free_space(self, points: np.ndarray, camera: "ViewCamera") -> np.ndarray:
        """(N,) True for points (tracking frame) the camera sees through: they project outside the
        person's (dilated) silhouette onto a pixel whose measured depth lies more than ``FREE_BEHIND_M``
        behind them, or onto a pixel without depth unless they are down where the floor was cut off."""
        uv, z = camera.project(points)
        H, W = self.mask.shape
        u, v = np.round(uv[:, 0]), np.round(uv[:, 1])
        inside = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        out = np.zeros(len(points), bool)
        i = np.flatnonzero(inside)
        ui, vi = u[i].astype(int), v[i].astype(int)
        seen = self.depth[vi, ui]
        free = ~self.mask_dilated()[vi, ui]
        with np.errstate(invalid="ignore"):
            behind = seen > z[i] + FREE_BEHIND_M
        unknown = ~np.isfinite(seen)
        if self.floor is not None:
            unknown &= self.height(points[i]) > FLOOR_BAND_M
        out[i] = free & (behind | unknown)
        return out

    def seen_through(self, points: np.ndarray, camera: "ViewCamera", margin_m: float) -> np.ndarray:
        """(N,) True for points (tracking frame) in view where the camera clearly sees past them: no pixel
        of the person's silhouette within ``margin_m`` (at the point's depth; a square of pixels around its
        pixel), and there a measured depth more than ``FREE_BEHIND_M`` behind the point or no measured
        depth in the square.  Stricter than :meth:`in_free_space`: a part fitted a few centimetres off a
        thin silhouette, or over the holes a depth sensor leaves around a person, does not count."""
        uv, z = camera.project(points)
        H, W = self.mask.shape
        u, v = np.round(uv[:, 0]), np.round(uv[:, 1])
        i = np.flatnonzero((z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H))
        ui, vi = u[i].astype(int), v[i].astype(int)
        if not hasattr(self, "_counts"):
            self._counts = (_summed_area(self.mask), _summed_area(np.isfinite(self.depth)))
        r = np.ceil(camera.intr.fx * margin_m / z[i]).astype(int)
        seen = self.depth[vi, ui]
        with np.errstate(invalid="ignore"):
            behind = seen > z[i] + FREE_BEHIND_M
        out = np.zeros(len(points), bool)
        person, measured = (_box_count(c, ui, vi, r) for c in self._counts)
        out[i] = (person == 0) & (behind | (measured == 0))
        return out

    def edge_tree(self) -> cKDTree:
        if not hasattr(self, "_edge_tree"):
            self._edge_tree = cKDTree(self.edge_pixels)
        return self._edge_tree


def _summed_area(mask: np.ndarray) -> np.ndarray:
    """(H + 1, W + 1) int64 summed-area table of a boolean image (a zero row and column first)."""
    out = np.zeros((mask.shape[0] + 1, mask.shape[1] + 1), np.int64)
    np.cumsum(np.cumsum(mask, axis=0), axis=1, out=out[1:, 1:])
    return out


def _box_count(table: np.ndarray, u: np.ndarray, v: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(N,) how many true pixels the image of ``table`` (:func:`_summed_area`) holds in the squares of
    half-width ``r`` around pixels ``(u, v)`` (clipped to the image)."""
    H, W = table.shape[0] - 1, table.shape[1] - 1
    u0, u1 = np.clip(u - r, 0, W), np.clip(u + r + 1, 0, W)
    v0, v1 = np.clip(v - r, 0, H), np.clip(v + r + 1, 0, H)
    return table[v1, u1] - table[v0, u1] - table[v1, u0] + table[v0, u0]


def _jump_cut(keep: np.ndarray, depth_m: np.ndarray, noise: float) -> np.ndarray:
    """(H, W) bool: the farther pixel of every 4-neighbour pair of ``keep`` whose depths differ by more
    than ``JUMP_M + noise z^2``."""
    z = np.where(keep, depth_m, np.nan)
    thr = JUMP_M + noise * np.nan_to_num(z, nan=0.0) ** 2
    zz = np.nan_to_num(z, nan=0.0)
    cut = np.zeros_like(keep)
    with np.errstate(invalid="ignore"):
        jump_v = np.abs(np.diff(z, axis=0)) > np.minimum(thr[1:], thr[:-1])
        jump_h = np.abs(np.diff(z, axis=1)) > np.minimum(thr[:, 1:], thr[:, :-1])
    far_v, far_h = zz[1:] > zz[:-1], zz[:, 1:] > zz[:, :-1]
    cut[1:] |= jump_v & far_v
    cut[:-1] |= jump_v & ~far_v
    cut[:, 1:] |= jump_h & far_h
    cut[:, :-1] |= jump_h & ~far_h
    return cut


def _components(keep, depth_m, noise):
    """``(labels (H, W), cut (H, W) bool, sizes (C,))``: the 4-connected components of ``keep`` with the
    pixels cut at depth jumps (:func:`_jump_cut`) taken out."""
    cut = _jump_cut(keep, depth_m, noise)
    labels, count = ndimage.label(keep & ~cut)
    return labels, cut, (np.bincount(labels.ravel())[1:] if count else np.zeros(0, np.int64))


def _centre(grid, mask) -> np.ndarray:
    """Median (3,) sensor-frame point of a component (every 16th of its pixels)."""
    return np.median(grid[mask][::16], axis=0)


def _candidates(labels, sizes, grid, min_pixels) -> list:
    """``[(label, pixels, centre (3,), mean column)]`` of the person-sized components: at least
    ``min_pixels``, ``PERSON_OF_LARGEST`` of the largest, and ``PERSON_EXTENT_M`` across in 3D."""
    out = []
    for lab in np.flatnonzero(sizes >= max(min_pixels, PERSON_OF_LARGEST * sizes.max(initial=0))) + 1:
        mask = labels == lab
        pts = grid[mask][::16]
        if len(pts) and np.linalg.norm(np.ptp(pts, axis=0)) >= PERSON_EXTENT_M:
            out.append((int(lab), int(sizes[lab - 1]), _centre(grid, mask), float(np.nonzero(mask)[1].mean())))
    return out


def _chosen(cands, width: int, choose: str, follow) -> int:
    """Index into ``cands`` of the person to track: the one nearest ``follow`` (the last frame's person,
    sensor frame) when given, else by ``choose`` (:data:`.options.PERSON_CHOICES`)."""
    if follow is not None:
        return int(np.argmin([np.linalg.norm(c[2] - follow) for c in cands]))
    key = {"centre": lambda c: abs(c[3] - 0.5 * (width - 1)), "nearest": lambda c: c[2][2],
           "largest": lambda c: -c[1], "left": lambda c: c[3], "right": lambda c: -c[3]}[choose]
    return min(range(len(cands)), key=lambda i: key(cands[i]))


def connected_person(keep: np.ndarray, grid: np.ndarray, depth_m: np.ndarray, noise: float,
                     min_share: float = MIN_PERSON_SHARE, reach: float = REACH_M, choose: str = "centre",
                     follow=None):
    """``(mask (H, W) bool, others)``: the person, one person-sized 4-connected component of ``keep``
    (neighbours further apart in depth than ``JUMP_M + noise z^2`` are not connected) chosen by ``choose``
    or nearest ``follow`` (:func:`_chosen`), plus the smaller components that come within ``reach`` metres
    of it in 3D (a forearm pointing at the camera is cut from the upper arm by a depth jump but stays next
    to it); ``others`` ``[(pixels, centre (3,) sensor frame)]`` the other person-sized components.  Empty
    when no component reaches ``min_share`` of the image."""
    labels, cut, sizes = _components(keep, depth_m, noise)
    cands = _candidates(labels, sizes, grid, min_share * keep.size) if len(sizes) else []
    if not cands:
        return np.zeros_like(keep), []
    pick = _chosen(cands, keep.shape[1], choose, follow)
    best = cands[pick][0]
    person = labels == best
    pts = grid[person]
    tree = cKDTree(pts[:: max(1, len(pts) // 4000)])
    merged = set()
    for lab in np.flatnonzero(sizes >= MIN_PART_PIXELS) + 1:
        if lab == best:
            continue
        part = labels == lab
        q = grid[part]
        d, _ = tree.query(q[:: max(1, len(q) // 200)], distance_upper_bound=reach)
        if np.isfinite(d).any():
            person |= part
            merged.add(int(lab))
    grown = ndimage.binary_dilation(person) & keep & cut & ~person   # cut pixels at its edge
    return person | grown, [(c[1], c[2]) for i, c in enumerate(cands) if i != pick and c[0] not in merged]


def _silhouette(person: np.ndarray):
    """Silhouette pixels (rows, cols) of the mask and their outward unit 2D normals (u, v)."""
    inner = ndimage.binary_erosion(person, border_value=0)
    edge = person & ~inner
    rows, cols = np.nonzero(edge)
    smooth = ndimage.gaussian_filter(person.astype(np.float32), 1.5)
    gu = ndimage.sobel(smooth, axis=1)[rows, cols]
    gv = ndimage.sobel(smooth, axis=0)[rows, cols]
    n = -np.stack((gu, gv), axis=1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
    return edge, rows, cols, n


def floor_margin(opts: dp.DepthOptions, z) -> np.ndarray:
    """Height (m) below which an observed point may be where the floor removal cut the person: the
    removal's tolerance plus its noise term, plus ``CONTACT_M``."""
    return opts.floor_tolerance + opts.depth_noise * np.asarray(z, float) ** 2 + CONTACT_M


def grid_stride(count: int, max_points: int) -> int:
    """Image-grid step giving at most about ``max_points`` of ``count`` pixels."""
    return max(1, int(np.ceil(np.sqrt(count / max(max_points, 1)))))


def observe(depth_m: np.ndarray, rays, camera: ViewCamera, opts: dp.DepthOptions, background=None, floor=None,
            max_points: int = 2500, max_edges: int = 400, floor_removed: bool = False, choose: str = "centre",
            follow=None) -> Observation:
    """One depth frame (metres, NaN invalid) -> :class:`Observation` of the person (possibly empty).
    ``floor`` (n, d) sensor frame: removed from the frame unless ``floor_removed`` (already done);
    ``choose``/``follow``: which person (:func:`connected_person`)."""
    grid = dp.backproject_grid(depth_m, rays)
    keep = dp.frame_mask(depth_m, grid, opts, background, None if floor_removed else floor)
    person, others = connected_person(keep, grid, depth_m, opts.depth_noise, choose=choose, follow=follow)
    count = int(person.sum())
    edge, er, ec, en = _silhouette(person)
    s = grid_stride(count, max_points)
    sub = np.zeros_like(person)
    off = s // 2
    sub[off::s, off::s] = True
    rows, cols = np.nonzero(person & sub)
    normals = dp.grid_normals(grid, rows, cols, mask=person) if len(rows) else np.zeros((0, 3))
    pts = grid[rows, cols]
    R, t = camera.R, camera.t
    plane = None
    if floor is not None:       # silhouette pixels where the floor was cut off are not occluding contours
        n = R @ np.asarray(floor[0], float)
        plane = (n, float(floor[1]) - float(n @ t))
        high = dp.plane_distance(grid[er, ec].astype(np.float64), floor) > floor_margin(opts, depth_m[er, ec])
        er, ec, en = er[high], ec[high], en[high]
    k = grid_stride(len(er), max_edges) ** 2
    er, ec, en = er[::k], ec[::k], en[::k]
    return Observation(points=pts.astype(np.float64) @ R.T + t, normals=np.asarray(normals, np.float64) @ R.T,
                       pixels=np.stack((cols, rows), 1).astype(np.float64), boundary=edge[rows, cols],
                       edge_points=grid[er, ec].astype(np.float64) @ R.T + t,
                       edge_pixels=np.stack((ec, er), 1).astype(np.float64), edge_normals=en,
                       mask=person, depth=depth_m, person_pixels=count, floor=plane, others=others,
                       centre=_centre(grid, person) if count else None)


def depth_image(points_cam: np.ndarray, intr) -> np.ndarray:
    """(H, W) float32 metres (NaN = nothing) of camera-frame points (N, 3) seen by ``intr``: each point
    fills its pixel, the nearest one wins (points imported from a depth image land back on their pixels)."""
    z = np.full(intr.height * intr.width, np.inf)
    p = np.asarray(points_cam, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(intr.fx * p[:, 0] / p[:, 2] + intr.cx)
        v = np.round(intr.fy * p[:, 1] / p[:, 2] + intr.cy)
    ok = (p[:, 2] > 0) & (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
    np.minimum.at(z, (v[ok] * intr.width + u[ok]).astype(np.int64), p[ok, 2])
    z = z.reshape(intr.height, intr.width).astype(np.float32)
    z[~np.isfinite(z)] = np.nan
    return z
