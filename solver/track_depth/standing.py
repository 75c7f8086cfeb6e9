"""Does a fitted body stand as a person does (ours; the report must not call an upside-down or folded fit
"tracked")?  Checked along the recording's up (:mod:`.orientation`) on the posed joints and the points:

* the head not below the hips (an upside-down fit);
* no foot above the hips (a leg folded up onto other data);
* with a floor: when the person's points reach down to it (standing on it), the lower foot near it;
* each part (:mod:`.out_of_view`) in view mostly where the camera sees the person, not where it clearly
  sees past it (:meth:`.observation.Observation.seen_through`: the sensor's holes around a person and a
  hand fitted a few centimetres off a thin silhouette are small errors, not a wrong pose).

The pipeline searches the limbs again on a fit with findings and starts a fit that does not stand (the
first three) anew; what remains is reported ``doubtful``.
"""
from __future__ import annotations

import numpy as np

from ..roles import role_bones
from .out_of_view import part_name
from .visibility import in_view

HEAD_BELOW_M = 0.05      # the head may dip this far below the hips (bending down) before it is upside down
FOOT_ABOVE_M = 0.0       # a foot higher than the hips by more than this is folded up
REACHES_FLOOR_M = 0.15   # the person's lowest points this near the floor: they stand on it
FOOT_OFF_FLOOR_M = 0.35  # ...and then the lower foot joint (ankle) is no higher than this
FREE_SHARE = 0.6         # a part with more of its in-view points in free space sits on nothing
FREE_MARGIN_M = 0.06     # ... where no depth was measured within this distance (at the point's depth)
MIN_IN_VIEW = 30       # smaller parts (hands) are too few points to judge


class Standing:
    """The roles the checks need, from a tracking body's model (none: nothing is checked)."""

    def __init__(self, body, parts):
        roles = role_bones(body.model.skeleton.names)
        self.hips = roles.get("hips")
        self.head = roles.get("head", roles.get("neck"))
        self.feet = [(part_name(r), roles[r]) for r in ("foot.L", "foot.R") if r in roles]
        self.parts = parts

    def findings(self, body, pose, obs, camera, up, posed=None) -> tuple:
        """``(stance, parts)``: readable findings on how ``pose`` (one frame; ``posed`` the body posed by
        it when known) stands and on parts the camera sees through, on ``obs`` (both empty when it passes)."""
        posed = body.pose(pose) if posed is None else posed
        return self._stance(posed, obs, up), self._in_free_space(posed, obs, camera)

    def _stance(self, posed, obs, up) -> list:
        out = []
        if self.hips is not None and self.head is not None:
            h = posed.joints @ up
            if h[self.head] < h[self.hips] - HEAD_BELOW_M:
                out.append(f"head {h[self.hips] - h[self.head]:.2f} m below the hips (upside down)")
            for name, f in self.feet:
                if h[f] > h[self.hips] + FOOT_ABOVE_M:
                    out.append(f"{name} {h[f] - h[self.hips]:.2f} m above the hips")
        if obs.floor is not None and self.feet and len(obs.points):
            low = float(np.percentile(obs.height(obs.points), 0.5))
            foot = float(obs.height(posed.joints[[b for _, b in self.feet]]).min())
            if low < REACHES_FLOOR_M and foot > FOOT_OFF_FLOOR_M:
                out.append(f"feet {foot:.2f} m above the floor the person stands on")
        return out

    def _in_free_space(self, posed, obs, camera) -> list:
        uv, z = camera.project(posed.points)
        seen = in_view(uv, z, camera.intr)
        through = None
        out = []
        for role, _, _, rows, _ in self.parts.parts:
            r = rows[seen[rows]]
            if len(r) < MIN_IN_VIEW:
                continue
            if through is None:
                through = obs.seen_through(posed.points, camera, FREE_MARGIN_M)
            if through[r].mean() > FREE_SHARE:
                out.append(f"{part_name(role)} where the camera sees through")
        return out
