"""Start hypotheses that aim a limb at capture a fit leaves unexplained.

A searched fit that lays a limb on the wrong surface (a forearm folded onto the belly while the capture's
forearm hangs by the thigh) leaves the limb's own capture unexplained, and the truth-free checks find
that region (:func:`solver.tracking.checks.check_frame`, its ``centre``).  From such a fit, each limb
segment whose posed joint is within the limb's reach of a region's centre is turned, alone and about
that joint, so that its axis points at the centre; the caller fits these starts and keeps one only when
it explains the capture better.  Any rig whose limb bones have roles; lengths from the rig's own rest
mesh, so a learned rig's joints serve as well as a designed one's.

Conventions: the pose increment of bone b is a rotation vector in the bone's local axes applied on the
right (``q_b <- q_b exp(delta)``, :func:`solver.rig.jacobians.apply_pose_increment`); with the rest
frame ``F_b`` and the posed part's rotation ``R`` (the chain map without its scale), a world rotation
``omega`` about the joint is ``delta = F_b^T R^T omega``.  Metres.
"""
from __future__ import annotations

import numpy as np

from ..rig.jacobians import apply_pose_increment
from ..rig.kinematics import forward_kinematics
from ..rig.model import Poses
from ..roles import role_bones
from .start_poses import subtree_masks

SEGMENTS = tuple(f"{role}.{side}" for side in "LR" for role in ("upper_arm", "forearm", "thigh", "shin"))
REACH_SLACK = 1.2       # a centre farther from the joint than this times the limb's reach is not the limb's
NEAREST = 0.05          # ... nor one nearer than this (m): the direction to it is noise


def aimed_starts(model, pose: Poses, centres) -> list:
    """One-frame :class:`Poses`: ``pose`` with one limb segment (:data:`SEGMENTS`, by role) turned about its
    posed joint to point at one of ``centres (K, 3)``, for every segment that can reach it (module
    docstring).  The segment's children keep their local rotations."""
    sk = model.skeleton
    roles = role_bones(sk.names)
    Rm, tm = forward_kinematics(sk, pose)
    reach = limb_reach(model)
    out = []
    for centre in np.asarray(centres, dtype=np.float64).reshape(-1, 3):
        for role in SEGMENTS:
            b = roles.get(role)
            if b is None:
                continue
            scale = np.cbrt(np.linalg.det(Rm[0, b]))
            joint = Rm[0, b] @ sk.heads[b] + tm[0, b]
            to = centre - joint
            if not NEAREST <= np.linalg.norm(to) <= REACH_SLACK * scale * reach[b]:
                continue
            omega = turn_between(Rm[0, b] @ (sk.tails[b] - sk.heads[b]), to)
            out.append(turned_about_joint(model, pose, b, omega, Rm[0, b] / scale))
    return out


def turned_about_joint(model, pose: Poses, bone: int, omega, R=None) -> Poses:
    """``pose`` with ``bone`` (its subtree with it) turned by the world rotation vector ``omega (3,)``
    about its posed joint (module docstring's convention); ``R (3, 3)``: the posed part's rotation without
    its scale, when the caller has it."""
    sk = model.skeleton
    if R is None:
        Rm, _ = forward_kinematics(sk, pose)
        R = Rm[0, bone] / np.cbrt(np.linalg.det(Rm[0, bone]))
    delta = np.zeros((1, 4 + 3 * sk.num_bones))
    delta[0, 4 + 3 * bone:7 + 3 * bone] = sk.frames[bone].T @ R.T @ omega
    return apply_pose_increment(pose, delta)


def limb_reach(model) -> np.ndarray:
    """``(B,)`` per bone the largest rest distance from its joint to a vertex of its subtree (m)."""
    sk = model.skeleton
    below = subtree_masks(sk.parents)
    reach = np.zeros(sk.num_bones)
    for a in range(sk.num_bones):
        mine = below[a][model.anchor]
        if mine.any():
            reach[a] = np.linalg.norm(model.rest_vertices[mine] - sk.heads[a], axis=1).max()
    return reach


def turn_between(d, u) -> np.ndarray:
    """``(3,)`` the shortest world rotation vector taking direction ``d`` to direction ``u`` (any axis
    normal to ``d`` when they are opposite)."""
    d, u = d / np.linalg.norm(d), u / np.linalg.norm(u)
    axis = np.cross(d, u)
    sin, cos = np.linalg.norm(axis), float(np.clip(d @ u, -1.0, 1.0))
    if sin < 1e-12:
        if cos > 0:
            return np.zeros(3)
        axis = np.cross(d, np.eye(3)[np.argmin(np.abs(d))])
        return np.pi * axis / np.linalg.norm(axis)
    return np.arctan2(sin, cos) * axis / sin
