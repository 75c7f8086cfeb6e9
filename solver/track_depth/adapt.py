"""The built-in template adapted to the person while tracking (depth-camera tracking dissertation ch. 5
§4.6-4.7 and ch. 6 Algorithm 4): a uniform size from the person's observed height before the first
frame; then on each of the first ``size_frames`` frames the pose and the body alternate: the macro shape
coefficients (:mod:`.body_shape`, ours), then the per-part lengths on top of that shape
(:mod:`.body_size`), both pooled over the frames adapted so far, then the pose again."""
from __future__ import annotations

import dataclasses

import numpy as np

from . import icp
from ..tracking.blend_body import BlendBody
from .body_shape import ShapeTerms, same_world_pose, solve_coefficients
from .body_size import SCALE_RANGE, FramePairs, scaled_model, solve_scales
from .initialise import cut_edges
from .observation import floor_margin
from .orientation import rest_height
from .surface import SurfaceFit
from .visibility import visible

FACING_COS = 0.5         # surface offsets only from points facing the camera (grazing pairs are biased)
SIZE_ROUNDS = 3          # pose <-> body alternations per adaptation frame


def observed_height(obs, up) -> float:
    """The person's extent along ``up`` (0.5th to 99.5th percentile of the observed points), metres."""
    h = obs.points @ (up / np.linalg.norm(up))
    lo, hi = np.percentile(h, [0.5, 99.5])
    return float(hi - lo)


@dataclasses.dataclass
class BodyState:
    """The adapted body: macro ``coefficients`` (K,) and per-part ``scales`` (B,) on top of that shape."""
    coefficients: np.ndarray
    scales: np.ndarray


class TemplateAdaptation:
    """Adapts ``template`` (:class:`.template.TemplateBody`) to the person (see the module docstring)."""

    def __init__(self, template, options, depth_options, camera_centre):
        self.template, self.opts = template, options
        self.depth_options, self.camera_centre = depth_options, camera_centre
        self.terms = ShapeTerms(template)
        B = template.base.skeleton.num_bones
        self.state = BodyState(np.zeros(template.num_basis), np.ones(B))
        self.frames = {}
        self.done = 0
        self.surface = None
        self.since = 0

    def model(self):
        return scaled_model(self.template.shaped(self.state.coefficients), self.state.scales)

    def start_model(self, obs, up):
        """The template scaled uniformly to the observed height (the floor removal takes about 2 cm off
        the feet), unless the person is cut by the image's top or bottom edge (then the template's size)."""
        body = rest_height(self.template.base)
        s = 1.0 if any(cut_edges(obs)) else np.clip((observed_height(obs, up) + 0.02) / body, *SCALE_RANGE)
        self.state.scales = np.full(len(self.state.scales), s)
        return self.model()

    def wants(self) -> bool:
        return self.opts.adapt_size and self.done < self.opts.size_frames

    def surface_step(self, body, pose, obs, camera):
        """After the size frames: record the frame's pairs for the surface and, every ``surface_every``
        frames, return a body with the displaced rest surface (else None)."""
        if not self.opts.adapt_surface or self.wants():
            return None
        if self.surface is None:
            self.surface = SurfaceFit(body.model)
        posed = body.pose(pose)
        vis = np.flatnonzero(visible(posed.points, posed.normals, camera, self.opts.visibility_tolerance))
        rows, targets = icp.surface_pairs(body, posed, vis, obs, self.opts)
        ray = posed.points[rows] - camera.centre
        facing = (posed.normals[rows] * ray).sum(axis=1) < -FACING_COS * np.linalg.norm(ray, axis=1)
        self.surface.add_frame(body.ids[rows[facing]], targets[facing], pose, camera.centre)
        self.since += 1
        if self.since < self.opts.surface_every:
            return None
        self.since = 0
        return BlendBody(self.surface.displaced(), ids=body.ids)

    def contact(self, posed, obs, ids):
        """(vertex id, n, d): the lowest model point stands on the floor, when the person's lowest
        observed points reach down to where the floor removal cuts; else None."""
        if obs.floor is None:
            return None
        h = obs.height(obs.points)
        z = np.linalg.norm(obs.points[np.argmin(h)] - self.camera_centre)
        if float(np.percentile(h, 0.5)) > floor_margin(self.depth_options, z) + 0.02:
            return None
        return int(ids[np.argmin(obs.height(posed.points))]), obs.floor[0], obs.floor[1]

    def _record(self, k, body, pose, obs, camera):
        posed = body.pose(pose)
        vis = np.flatnonzero(visible(posed.points, posed.normals, camera, self.opts.visibility_tolerance))
        rows, targets = icp.surface_pairs(body, posed, vis, obs, self.opts)
        base_pose = same_world_pose(body.model.skeleton, self.template.base.skeleton, pose)
        self.frames[k] = FramePairs(body.ids[rows], targets, base_pose, self.contact(posed, obs, body.ids))

    def _solve(self):
        frames = list(self.frames.values())
        self.state.coefficients = solve_coefficients(self.terms, frames)
        shaped = self.template.shaped(self.state.coefficients)
        in_shape = [dataclasses.replace(f, pose=same_world_pose(self.template.base.skeleton, shaped.skeleton, f.pose))
                    for f in frames]
        self.state.scales = solve_scales(shaped, in_shape, np.ones(len(self.state.scales)))
        return scaled_model(shaped, self.state.scales)

    def adapt(self, k, body, pose, obs, camera, limits, fit_frame):
        """Alternate pose and body on frame k; returns ``(body, fit)`` with the adapted body."""
        fit = None
        for _ in range(SIZE_ROUNDS):
            self._record(k, body, pose, obs, camera)
            model = self._solve()
            pose = same_world_pose(body.model.skeleton, model.skeleton, pose)
            body = BlendBody(model, ids=body.ids)
            fit = fit_frame(body, obs, camera, pose, self.opts, limits)
            pose = fit.pose
        self.done += 1
        return body, fit
