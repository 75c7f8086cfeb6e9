"""The start pose of a depth recording without user action (depth-camera tracking dissertation ch. 3's
pose-database idea, ch. 5 §5.3 and ch. 6 §6.5 need only the rough global orientation): the person stands
roughly upright facing the camera (within +-45 deg).  Hypotheses = facings every ``YAW_STEP`` deg in
+-``YAW_RANGE`` x a few body poses (rest + the generic body poses); each is placed on the observed points,
fitted by a few ICP iterations and scored by the observed points it leaves unexplained plus the model
points that land where the camera sees no person (free space); the best is fitted to convergence.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..geometry.rotations import matrix_to_quat, quat_mul, rotation_between
from ..rig.model import Poses
from ..tracking.body_poses import body_poses
from .limb_search import place_limbs
from .orientation import BLENDER_FRONT, BLENDER_UP, rest_axes, rest_height
from . import icp

YAW_RANGE = 45.0
YAW_STEP = 15.0
BODY_POSES = 4           # rest + 3 generic body poses
SCREEN_ITERATIONS = 5
EDGE_PIXELS = 2          # a silhouette this close to the image's top or bottom is cut by it


@dataclasses.dataclass
class Start:
    """The chosen ``fit`` (:class:`.icp.FrameFit`), its ``score`` and the number of hypotheses ``tried``."""
    fit: object
    score: float
    tried: int


def facing_rotation(up: np.ndarray, towards: np.ndarray, yaw_deg: float,
                    axes=(BLENDER_UP, BLENDER_FRONT)) -> np.ndarray:
    """(3, 3) world rotation taking the model's up ``axes[0]`` to ``up`` and its front ``axes[1]`` to
    ``towards`` (made horizontal), then turned by ``yaw_deg`` about ``up``."""
    up = up / np.linalg.norm(up)
    R1 = rotation_between(np.asarray(axes[0], float), up)
    front = R1 @ np.asarray(axes[1], float)
    t = towards - (towards @ up) * up
    t /= max(np.linalg.norm(t), 1e-12)
    angle = np.arctan2(np.cross(front, t) @ up, front @ t) + np.radians(yaw_deg)
    K = np.array([[0, -up[2], up[1]], [up[2], 0, -up[0]], [-up[1], up[0], 0]])
    R2 = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    return R2 @ R1


def placed(model, body_rot: np.ndarray, world: np.ndarray, centre: np.ndarray, scale: float = 1.0) -> Poses:
    """``body_rot`` (B, 4) local rotations with the root turned by ``world`` (3, 3) and translated so
    the rest body's box centre lands on ``centre``."""
    sk = model.skeleton
    rot = body_rot.copy()
    rot[0] = quat_mul(matrix_to_quat(sk.frames[0].T @ world @ sk.frames[0]), body_rot[0])
    v = model.rest_vertices
    c_model = 0.5 * (v.min(0) + v.max(0))
    h0 = sk.heads[0]
    t = centre - h0 - scale * world @ (c_model - h0)
    return Poses(rot[None], t[None], np.array([scale]))


def cut_edges(obs, sides: bool = False) -> tuple:
    """``(top, bottom)`` (with ``sides``: ``(top, bottom, left, right)``): whether the person's silhouette
    touches that edge of the image."""
    def ends(any_along):
        idx = np.flatnonzero(any_along)
        n = len(any_along)
        return (len(idx) > 0 and idx[0] <= EDGE_PIXELS), (len(idx) > 0 and idx[-1] >= n - 1 - EDGE_PIXELS)
    out = ends(obs.mask.any(axis=1))
    return out + ends(obs.mask.any(axis=0)) if sides else out


def body_centre(obs, camera, up, height: float) -> np.ndarray:
    """Centre of the person's body box (``height`` metres tall): along ``up`` the middle of the observed
    points' 1-99 percentile range, or ``height``/2 below their top (above their bottom) when the image's
    bottom (top) edge cuts the person; across it their median moved 10 cm away from the camera (the camera
    sees the front)."""
    up = up / np.linalg.norm(up)
    h = obs.points @ up
    lo, hi = np.percentile(h, [1, 99])
    top_cut, bottom_cut = cut_edges(obs)
    middle = 0.5 * (lo + hi)
    if bottom_cut and not top_cut:
        middle = hi - 0.5 * height
    elif top_cut and not bottom_cut:
        middle = lo + 0.5 * height
    c = np.median(obs.points, axis=0)
    ray = c - camera.centre
    ray -= (ray @ up) * up
    c = c + 0.1 * ray / max(np.linalg.norm(ray), 1e-12)
    return c + (middle - c @ up) * up


def free_space(posed, obs, camera) -> float:
    """Share of the model points in view that project outside the person's (dilated) silhouette."""
    uv, z = camera.project(posed.points)
    H, W = obs.mask.shape
    u, v = np.round(uv[:, 0]), np.round(uv[:, 1])
    ok = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    if not ok.any():
        return 1.0
    return float((~obs.mask_dilated()[v[ok].astype(int), u[ok].astype(int)]).mean())


def score(body, fit, obs, camera) -> float:
    """Lower is better: unexplained observed points + model points in free space."""
    posed = fit.posed if fit.posed is not None else body.pose(fit.pose)
    return (1.0 - fit.near_share) + free_space(posed, obs, camera)


def hypotheses(model, up, towards, centre, scale: float = 1.0):
    """Start poses: facings x body poses (see the module docstring)."""
    bodies = body_poses(model.skeleton, count=2 * BODY_POSES - 1).rotations[:BODY_POSES]
    yaws = np.arange(-YAW_RANGE, YAW_RANGE + 1e-9, YAW_STEP)
    axes = rest_axes(model)
    for yaw in yaws:
        world = facing_rotation(up, towards, yaw, axes)
        for rot in bodies:
            yield placed(model, rot, world, centre, scale)


def _holding(parts, limits, body, pose, camera):
    """``(held bones, pose, limits)``: the parts of ``pose`` out of view set and held (:mod:`.out_of_view`)."""
    if parts is None:
        return (), pose, limits
    return parts.hold(body, pose, camera, limits)


def initialise(body, obs, camera, up, options, limits=(), scale: float = 1.0, parts=None) -> Start:
    """The best start pose for the observation ``obs`` (see the module docstring); ``parts``
    (:class:`.out_of_view.Parts`) holds the parts out of view."""
    height = scale * rest_height(body.model)
    centre = body_centre(obs, camera, up, height)
    towards = camera.centre - centre
    best, tried = None, 0
    fitter = icp.fit_frame        # closest points reach farther than the GMM's 2 cm posteriors
    for pose in hypotheses(body.model, up, towards, centre, scale):
        _, pose, held_limits = _holding(parts, limits, body, pose, camera)
        fit = fitter(body, obs, camera, pose, options, held_limits, iterations=SCREEN_ITERATIONS)
        s = score(body, fit, obs, camera)
        tried += 1
        if best is None or s < best[0]:
            best = (s, fit)
    held, pose, _ = _holding(parts, limits, body, best[1].pose, camera)
    start = place_limbs(body, pose, obs, camera, options.near_m, up, held=held)
    _, start, held_limits = _holding(parts, limits, body, start, camera)
    fit = fitter(body, obs, camera, start, options, held_limits)
    return Start(fit, score(body, fit, obs, camera), tried)
