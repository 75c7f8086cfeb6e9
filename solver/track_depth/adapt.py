"""The built-in template adapted to the person while tracking (depth-camera tracking dissertation ch. 5
§4.6-4.7 and ch. 6 Algorithm 4): a uniform size from the person's observed height before the first
frame, then on each of the first ``size_frames`` frames the pose and the per-part lengths
(:mod:`.body_size`) alternate, each solved on the tracker's point pairs, the lengths pooled over the
frames seen so far."""
from __future__ import annotations

import numpy as np

from . import icp
from .body import TrackingBody
from .body_size import SCALE_RANGE, SizeFit, scaled_model
from .observation import floor_margin
from .visibility import visible

SIZE_ROUNDS = 3          # pose <-> lengths alternations per adaptation frame


def observed_height(obs, up) -> float:
    """The person's extent along ``up`` (1st to 99.5th percentile of the observed points), metres."""
    h = obs.points @ (up / np.linalg.norm(up))
    lo, hi = np.percentile(h, [0.5, 99.5])
    return float(hi - lo)


class TemplateAdaptation:
    """State of the adaptation: the unscaled ``template`` model, the accumulated :class:`SizeFit` and the
    frames adapted so far."""

    def __init__(self, template, options, depth_options, camera_centre):
        self.template, self.opts = template, options
        self.depth_options, self.camera_centre = depth_options, camera_centre
        self.size = SizeFit(template)
        self.done = 0

    def start_scales(self, obs, up) -> np.ndarray:
        """One scale for every part from the observed height over the template's (upright, feet on the
        floor: the floor removal takes about 2 cm off the feet)."""
        v = self.template.rest_vertices
        body = float(np.ptp(v[:, 2]))                       # template: metres, Z up
        s = np.clip((observed_height(obs, up) + 0.02) / body, *SCALE_RANGE)
        self.size.scales = np.full(self.template.skeleton.num_bones, s)
        self.size.prior = self.size.scales.copy()
        return self.size.scales

    def wants(self) -> bool:
        return self.opts.adapt_size and self.done < self.opts.size_frames

    def contact(self, posed, obs):
        """The lowest model point on the floor, when the person's lowest observed points reach down to
        where the floor removal cuts (standing); else None."""
        if obs.floor is None:
            return None
        low = float(np.percentile(obs.height(obs.points), 0.5))
        z = np.linalg.norm(obs.points[np.argmin(obs.height(obs.points))] - self.camera_centre)
        if low > floor_margin(self.depth_options, z) + 0.02:
            return None
        row = int(np.argmin(obs.height(posed.points)))
        return row, obs.floor[0], obs.floor[1]

    def adapt(self, k, body, pose, obs, camera, limits, fit_frame):
        """Alternate pose and lengths on frame k; returns ``(body, fit)`` with the rescaled body."""
        fit = None
        for _ in range(SIZE_ROUNDS):
            posed = body.pose(pose)
            vis = np.flatnonzero(visible(posed.points, posed.normals, camera, self.opts.visibility_tolerance))
            rows, targets = icp.surface_pairs(body, posed, vis, obs, self.opts)
            self.size.add_frame(k, body.ids, pose, rows, targets, self.contact(posed, obs))
            scales = self.size.solve()
            body = TrackingBody(scaled_model(self.template, scales), ids=body.ids)
            fit = fit_frame(body, obs, camera, pose, self.opts, limits)
            pose = fit.pose
        self.done += 1
        return body, fit
