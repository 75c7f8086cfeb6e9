"""Start hypotheses that bend a lost fit's knee or elbow the right way.

A limb is nearly a cylinder about its upper segment, so a search can end with the upper arm (or thigh)
turned half round about itself and the elbow (knee) bent backwards, the forearm lying in the capture's
forearm; the truth-free checks find the hinge bent backwards beyond its limit
(:func:`solver.tracking.joint_limits.hinge_angles`).  From such a fit the upper segment is turned half
round about its posed line (joint to joint) and the lower segment then turned about its joint back to
where it pointed: the same limb line, bent the other way about the flipped flexion axis.  The caller fits
these starts from the coarse stage on.  Conventions: :mod:`solver.tracking.aimed_starts`.
"""
from __future__ import annotations

import numpy as np

from ..rig.kinematics import forward_kinematics
from ..rig.model import Poses
from .aimed_starts import turn_between, turned_about_joint
from .joint_limits import Hinge, hinge_points


def flipped_hinge_start(model, pose: Poses, hinge: Hinge) -> Poses:
    """``pose`` (one frame) with ``hinge`` bent the other way and its limb line kept (module docstring);
    the end segment and everything below keep their local rotations."""
    before = _joints(model, pose, hinge)
    line = before[1] - before[0]
    turned = turned_about_joint(model, pose, hinge.points[0][0], np.pi * line / np.linalg.norm(line))
    after = _joints(model, turned, hinge)
    return turned_about_joint(model, turned, hinge.points[1][0],
                              turn_between(after[2] - after[1], before[2] - before[1]))


def _joints(model, pose, hinge):
    Rm, tm = forward_kinematics(model.skeleton, pose)
    return hinge_points(hinge, Rm[0], tm[0])
