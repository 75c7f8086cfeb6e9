"""Joint limits of the depth tracker (ours: the dissertation's trackers have none, ch. 5 §5.5 names the
drift of weakly seen joints as a failure): soft box limits on each joint's bone-local rotation vector,
from the generic human prior mapped by bone names (:func:`solver.tracking.pose_prior.generic_prior`), plus a
weak pull towards the middle of the box scaled by 1/width^2, so joints the data hardly sees (hip girdle,
clavicles, spine segments) do not wander while a limb's wide range is barely pulled."""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import quat_to_rotvec
from ..tracking.pose_prior import generic_prior, rotvec_increment_jacobian

BOX_WEIGHT = 10.0      # m^2 per rad^2 outside the box
CENTRE_WEIGHT = 0.02   # m^2 per (box width)^2 away from the middle
HOLD_WEIGHT = 1000.0   # m^2 per rad^2 away from a held rotation (a part out of view keeps it)


class JointLimits:
    """Box ``lower``/``upper`` (B, 3) radians (inf = free) and the bones that have one."""

    def __init__(self, skeleton, lower=None, upper=None, box_weight: float = BOX_WEIGHT,
                 centre_weight: float = CENTRE_WEIGHT):
        self.box_weight, self.centre_weight = box_weight, centre_weight
        if lower is None:
            prior = generic_prior(skeleton)
            lower, upper = prior.lower, prior.upper
        self.skeleton = skeleton
        self.lower, self.upper = np.asarray(lower, float), np.asarray(upper, float)
        self.bones = np.flatnonzero(np.isfinite(self.lower).all(axis=1) & np.isfinite(self.upper).all(axis=1))
        finite = np.isfinite(self.lower) & np.isfinite(self.upper)
        with np.errstate(invalid="ignore"):
            self.width = np.where(finite, np.maximum(self.upper - self.lower, np.radians(5.0)), np.inf)
        self.centre = np.where(finite, 0.5 * (np.where(finite, self.lower, 0) + np.where(finite, self.upper, 0)), 0.0)

    @classmethod
    def none(cls, skeleton) -> "JointLimits":
        inf = np.full((skeleton.num_bones, 3), np.inf)
        return cls(skeleton, -inf, inf)

    def add_to(self, system, posed, pose) -> None:
        """Rows on the limited bones' rotation increments (left increments in bone axes, mapped to the
        world-axes parameters through the parent's current rotation)."""
        b = self.bones
        if len(b) == 0:
            return
        sk = self.skeleton
        r = quat_to_rotvec(pose.rotations[0, b])
        # omega_b turns q_b by the left increment exp(F_bᵀ W_pᵀ omega_b); d log / d(left increment) is
        # the inverse left Jacobian J_l^{-1}(r) = J_r^{-1}(-r)
        Jlog = rotvec_increment_jacobian(-r)
        parent_world = posed.world[sk.parents[b]]
        to_local = np.swapaxes(sk.frames[b], 1, 2) @ np.swapaxes(parent_world, 1, 2)
        D = Jlog @ to_local                                     # (k, 3, 3)
        over = r - np.clip(r, self.lower[b], self.upper[b])
        pull = (r - self.centre[b]) / self.width[b]
        cols = 3 + 3 * b[:, None] + np.arange(3)                     # (k, 3) the bones' parameter columns
        system.add_blocks(cols, D, over, np.where(over != 0, self.box_weight, 0.0))
        if self.centre_weight > 0:
            scale = 1.0 / self.width[b]
            system.add_blocks(cols, D * scale[:, :, None], pull, np.full(pull.shape, self.centre_weight))

    def holding(self, bones, targets) -> "JointLimits":
        """These limits plus ``bones`` held at the bone-local rotation vectors ``targets`` (k, 3) by
        ``HOLD_WEIGHT`` (body parts out of the camera's view, :mod:`.out_of_view`)."""
        if len(bones) == 0:
            return self
        lower = np.full((self.skeleton.num_bones, 3), np.inf)
        lower[bones] = targets
        return _Both(self, JointLimits(self.skeleton, lower, lower.copy(), HOLD_WEIGHT, 0.0))


class _Both:
    """Two sets of limits added to the same system."""

    def __init__(self, first: JointLimits, second: JointLimits):
        self.first, self.second = first, second
        self.skeleton = first.skeleton

    def add_to(self, system, posed, pose) -> None:
        self.first.add_to(system, posed, pose)
        self.second.add_to(system, posed, pose)
