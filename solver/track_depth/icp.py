"""The ICP pose tracker of one frame (depth-camera tracking dissertation, ch. 5, §5.1-5.2; Algorithm 2):
point-to-point closest points from the visible model points, pruned by distance, normal angle, silhouette
points and relaxed bijectivity (Eq. 5.3, same main bone both ways), plus edge-to-edge pairs on the
silhouette (two-stage search: k nearest edge pixels in 2D, the closest of them in 3D) with the projective
edge rows of Eq. 5.4 (:class:`DepthPairs`, a data term of the tracking core); the linear system of
Eq. 5.6 with the priors is solved and the model re-posed until no visible point moves more than
``converged_m`` (:func:`solver.tracking.lm.iterate`).

Edge rows are metric (pixel error x depth / focal length, i.e. Eq. 5.4 divided by the focal length), so
``edge_weight`` weighs them against the point rows in the same units (the dissertation's lambda_e =
1/max(W, H) weighs pixel-metre rows).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.spatial import cKDTree

from ..tracking.lm import iterate
from ..tracking.normal_equations import System
from .visibility import visible

GRAZING_COS = 0.35       # model points whose normal is this close to perpendicular to the view are contour points
MAX_TURN = 0.5           # largest joint rotation (rad) of one linear step; longer steps are shortened


@dataclasses.dataclass
class FrameFit:
    """``pose`` (one frame), ``iterations``, ``pairs`` / ``edges`` of the last iteration, ``near_share``
    of observed points within ``near_m`` of the model, their ``mean_m`` distance (capped at 0.2 m),
    ``seconds``; ``posed`` the body posed by ``pose`` (:class:`.body.PosedBody`, for the checks)."""
    pose: object
    iterations: int
    pairs: int
    edges: int
    near_share: float
    mean_m: float
    seconds: float
    posed: object = None


def surface_pairs(body, posed, vis, obs, opts):
    """Model rows (subset ids) and their observed targets (k, 3), Table 5.1 pruning plus Eq. 5.3."""
    if len(vis) == 0 or obs.empty:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    q = posed.points[vis]
    dist, j = obs.tree().query(q, distance_upper_bound=opts.max_distance)
    ok = np.isfinite(dist)
    j = np.where(ok, j, 0)
    ok &= ~obs.boundary[j]
    ok &= (posed.normals[vis] * obs.normals[j]).sum(axis=1) >= np.cos(np.radians(opts.max_normal_angle))
    rows, targets = vis[ok], obs.points[j[ok]]
    if len(rows):
        _, back = cKDTree(q).query(targets)
        same = body.main_bone[vis[back]] == body.main_bone[rows]
        rows, targets = rows[same], targets[same]
    return rows, targets


def data_pairs(body, posed, vis, obs, opts, sample: int = 1000):
    """Observed points (a grid-spread sample) paired with their nearest visible model point, the same
    pruning as :func:`surface_pairs`: data the model does not explain pull the nearest part (ours; the
    dissertation's ch. 5 pairs model points only)."""
    if len(vis) == 0 or obs.empty:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    pick = np.arange(0, len(obs.points), max(1, len(obs.points) // sample))
    pick = pick[~obs.boundary[pick]]
    x = obs.points[pick]
    tree = cKDTree(posed.points[vis])
    dist, i = tree.query(x, distance_upper_bound=opts.max_distance)
    ok = np.isfinite(dist)
    i = np.where(ok, i, 0)
    ok &= (posed.normals[vis[i]] * obs.normals[pick]).sum(axis=1) >= np.cos(np.radians(opts.max_normal_angle))
    return vis[i[ok]], x[ok]


def contour_normals_2d(points, normals, camera):
    """(k, 2) image directions in which the points' normals point (unit)."""
    c = camera.to_camera(points)
    n = normals @ camera.R
    z = c[:, 2:3]
    d = np.stack((camera.intr.fx * (n[:, 0] - c[:, 0] / z[:, 0] * n[:, 2]),
                  camera.intr.fy * (n[:, 1] - c[:, 1] / z[:, 0] * n[:, 2])), axis=1)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)


def edge_pairs(body, posed, vis, obs, camera, opts):
    """Model contour rows (subset ids) and their matched silhouette pixels (k, 2) (Table 5.1, Fig. 5.3b)."""
    none = np.zeros(0, np.int64), np.zeros((0, 2))
    if len(vis) == 0 or len(obs.edge_pixels) == 0:
        return none
    P, N = posed.points[vis], posed.normals[vis]
    ray = P - camera.centre
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    cont = np.flatnonzero(np.abs((N * ray).sum(axis=1)) < GRAZING_COS)
    if len(cont) == 0:
        return none
    uv, _ = camera.project(P[cont])
    k = min(opts.edge_candidates, len(obs.edge_pixels))
    _, nb = obs.edge_tree().query(uv, k)
    nb = nb.reshape(len(cont), k)
    d3 = np.linalg.norm(obs.edge_points[nb] - P[cont][:, None], axis=2)
    best = nb[np.arange(len(cont)), np.argmin(d3, axis=1)]
    ok = np.min(d3, axis=1) <= opts.max_distance
    n2 = contour_normals_2d(P[cont], N[cont], camera)
    ok &= (n2 * obs.edge_normals[best]).sum(axis=1) >= np.cos(np.radians(opts.edge_normal_angle)) - 1e-9
    rows, best = vis[cont[ok]], best[ok]
    if len(rows):
        _, back = cKDTree(P).query(obs.edge_points[best])
        same = body.main_bone[vis[back]] == body.main_bone[rows]
        rows, best = rows[same], best[same]
    return rows, obs.edge_pixels[best]


def edge_rows(points, pixels, camera):
    """Metric projective rows of Eq. 5.4 for points (k, 3) matched to pixels (k, 2): directions h (2k, 3)
    in the tracking frame and residuals e (2k,) with ``h . (p - camera centre) = e``."""
    intr = camera.intr
    k = len(points)
    hc = np.zeros((2 * k, 3))
    hc[:k, 0] = 1.0
    hc[:k, 2] = (intr.cx - pixels[:, 0]) / intr.fx
    hc[k:, 1] = 1.0
    hc[k:, 2] = (intr.cy - pixels[:, 1]) / intr.fy
    h = hc @ camera.R.T
    e = (h * (np.concatenate([points, points]) - camera.centre)).sum(axis=1)
    return h, e


def coverage(body, posed, obs, near_m: float, sample: int = 800):
    """Share of observed points within ``near_m`` of a model point and their mean distance (capped)."""
    if obs.empty:
        return 0.0, float("nan")
    pts = obs.points[:: max(1, len(obs.points) // sample)]
    d, _ = cKDTree(posed.points).query(pts, distance_upper_bound=0.2)
    d = np.minimum(d, 0.2)
    return float((d <= near_m).mean()), float(d.mean())


def build_system(body, posed, obs, camera, opts):
    """The linearisation (:class:`solver.tracking.terms.Linear`) of one ICP iteration's rows, the rows it
    used, their lever arms and the number of edge pairs."""
    vis = np.flatnonzero(visible(posed.points, posed.normals, camera, opts.visibility_tolerance))
    rows, targets = surface_pairs(body, posed, vis, obs, opts)
    if opts.data_weight > 0:
        drows, dtargets = data_pairs(body, posed, vis, obs, opts)
        w = np.concatenate([np.full(len(rows), opts.point_weight), np.full(len(drows), opts.data_weight)])
        rows, targets = np.concatenate([rows, drows]), np.concatenate([targets, dtargets])
    else:
        w = np.full(len(rows), opts.point_weight)
    system = System(body, posed)
    a = body.lever_arms(posed, rows)
    r = posed.points[rows] - targets
    if opts.plane_weight > 0:
        n = posed.normals[rows]
        system.add_projected(a, n, (n * r).sum(axis=1), opts.plane_weight * w / max(opts.point_weight, 1e-12))
    system.add_points(a, r, w)
    erows, pix = edge_pairs(body, posed, vis, obs, camera, opts) if opts.edge_weight > 0 else ((), ())
    if len(erows):
        h, e = edge_rows(posed.points[erows], pix, camera)
        ae = body.lever_arms(posed, erows)
        system.add_projected(np.concatenate([ae, ae]), h, e, np.full(len(e), opts.edge_weight))
    if obs.floor is not None and opts.floor_weight > 0:
        add_floor_rows(system, body, posed, obs, opts.floor_weight)
    return system.linear(), rows, a, len(erows)


class DepthPairs:
    """The ICP data term of one frame for :func:`solver.tracking.lm.iterate`: at every pose the pairs
    of :func:`build_system` found anew (None below 6 pairs); converged when the step moves no paired point
    by more than ``converged_m`` (linearised motion).  ``pairs`` / ``edges``: counts of the last pose."""
    prior_scale = 1.0

    def __init__(self, obs, camera, opts):
        self.obs, self.camera, self.opts = obs, camera, opts
        self.pairs = self.edges = 0
        self._arms = None

    def linearise(self, body, posed):
        lin, rows, self._arms, self.edges = build_system(body, posed, self.obs, self.camera, self.opts)
        self.pairs = len(rows)
        return lin if len(rows) >= 6 else None

    def converged(self, body, posed, moved, step) -> bool:
        return np.linalg.norm(body.motion(posed, step, self._arms), axis=1).max() < self.opts.converged_m


def add_floor_rows(system, body, posed, obs, weight: float) -> None:
    """Model points below the floor plane are pushed up onto it (the body cannot sink into the floor)."""
    below = np.flatnonzero(obs.height(posed.points) < 0)
    if len(below):
        n = np.broadcast_to(obs.floor[0], (len(below), 3))
        system.add_projected(body.lever_arms(posed, below), n, obs.height(posed.points[below]),
                             np.full(len(below), weight))


def fit_frame(body, obs, camera, pose, opts, prior=(), iterations=None) -> FrameFit:
    """ICP from ``pose`` (one frame) on the observation ``obs`` (see the module docstring); ``prior``:
    terms of :mod:`solver.tracking.priors` (joint limits)."""
    t0 = time.perf_counter()
    data = DepthPairs(obs, camera, opts)
    pose, posed, it = iterate(body, pose, data, prior, opts.damping, MAX_TURN, iterations or opts.max_iterations)
    share, mean = coverage(body, posed, obs, opts.near_m)
    return FrameFit(pose, it, data.pairs, data.edges, share, mean, time.perf_counter() - t0, posed)
