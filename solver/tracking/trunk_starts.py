"""Start hypotheses that put a lost fit's trunk right: hips turned back under the chest, a body turned round.

A body's capture is nearly symmetric about the trunk's long axis below the waist, so a search can end with
the hips turned half round and the legs swapped (the left leg in the right leg's capture), explaining the
capture to a millimetre or two; the truth-free checks find the hips twisted from the chest beyond what a
trunk does (:func:`solver.tracking.joint_limits.trunk_twist`).  From such a fit the hips are turned back about
the spine so that the twist is gone, the chest and everything above it staying where it is, once with the
legs as they were (they come round with the hips) and once with each leg pointing as the other leg of the
fit points (the fit's legs lie in the capture's, swapped).  A whole body fitted facing away bends its
trunk backwards where the true one bends forwards (:func:`solver.tracking.joint_limits.trunk_back`); it is
turned round: each trunk bone half a turn about itself, the limbs aimed along the other side's, hands
and feet at rest on them.  The
caller fits these starts from the coarse stage on.

Conventions as :mod:`solver.tracking.aimed_starts`: a world rotation ``omega`` about bone b's joint is
the local increment ``F_b^T R^T omega`` (``R``: the posed part's rotation without its scale).
"""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import matrix_to_quat, rotvec_to_matrix
from ..rig.jacobians import apply_pose_increment
from ..rig.kinematics import forward_kinematics
from ..rig.model import Poses
from ..roles import role_bones
from .aimed_starts import turn_between, turned_about_joint
from .joint_limits import signed_twist
from .start_poses import subtree_masks

LEG_SEGMENTS = ("thigh", "shin", "foot")
LIMB_SEGMENTS = ("upper_arm", "forearm", "thigh", "shin")
END_SEGMENTS = ("hand", "foot")


def untwisted_starts(model, pose: Poses, trunk) -> list:
    """Two one-frame :class:`Poses`: ``pose`` with the hips bone turned about its posed spine direction by
    minus its twist from the chest (``trunk``: ``(hips, chest, spine rest direction (3,), forward)`` as
    :func:`solver.tracking.checks.prepare` makes it), its legs kept, then swapped (module docstring)."""
    sk = model.skeleton
    hips, chest, axis, _ = trunk
    Rm, _ = forward_kinematics(sk, pose)
    R_hips = Rm[0, hips] / np.cbrt(np.linalg.det(Rm[0, hips]))
    R_chest = Rm[0, chest] / np.cbrt(np.linalg.det(Rm[0, chest]))
    omega = -signed_twist(R_chest.T @ R_hips, axis) * (R_hips @ axis)
    delta = np.zeros((1, 4 + 3 * sk.num_bones))
    delta[0, 4 + 3 * hips:7 + 3 * hips] = sk.frames[hips].T @ R_hips.T @ omega
    below = subtree_masks(sk.parents)
    if below[hips, chest]:                       # the chest hangs from the hips: its path turns back
        path = _child_towards(sk.parents, hips, chest)
        R_path = Rm[0, path] / np.cbrt(np.linalg.det(Rm[0, path]))
        delta[0, 4 + 3 * path:7 + 3 * path] = sk.frames[path].T @ R_path.T @ (-omega)
    turned = apply_pose_increment(pose, delta)
    return [turned, _swapped_legs(model, turned, pose)]


def _swapped_legs(model, start: Poses, fit: Poses) -> Poses:
    """``start`` with each leg segment (thigh, lower leg, foot by role, top-down) turned about its joint so
    that it points as the other side's segment points in ``fit``: the twisted fit's legs lie in the
    capture's legs, each in the other's."""
    sk = model.skeleton
    roles = role_bones(sk.names)
    Rf, _ = forward_kinematics(sk, fit)
    pose = start
    for segment in LEG_SEGMENTS:
        for side, other in (("L", "R"), ("R", "L")):
            b, partner = roles.get(f"{segment}.{side}"), roles.get(f"{segment}.{other}")
            if b is None or partner is None:
                continue
            Rm, _ = forward_kinematics(sk, pose)
            omega = turn_between(Rm[0, b] @ (sk.tails[b] - sk.heads[b]), Rf[0, partner] @ (sk.tails[partner] -
                                                                                          sk.heads[partner]))
            pose = turned_about_joint(model, pose, b, omega, Rm[0, b] / np.cbrt(np.linalg.det(Rm[0, b])))
    return pose


def _child_towards(parents, top, bone) -> int:
    """The child of ``top`` on the path from ``top`` down to ``bone`` (``bone`` below ``top``)."""
    while parents[bone] != top:
        bone = parents[bone]
    return bone


def turned_round_start(model, pose: Poses, trunk) -> Poses:
    """``pose`` facing the other way with the same trunk line: every bone from the hips to the head (by
    role, and the bones between them) turned half round about its own posed direction, each limb segment
    (:data:`LIMB_SEGMENTS`) then pointing as the other side's did, hands and feet (:data:`END_SEGMENTS`) at
    rest on their limbs (front and back differ there, so how they were turned facing away says nothing:
    the Kinect-like reach's first frame 70 mm off with them aimed too, 38 mm at rest); other bones keep
    their local rotations.  A fit facing away from the capture bends back where the body bends forward (the
    checks' trunk bend) with its limbs in the other side's capture."""
    sk = model.skeleton
    roles = role_bones(sk.names)
    Rm, _ = forward_kinematics(sk, pose)
    W = Rm[0] / np.cbrt(np.linalg.det(Rm[0]))[:, None, None]
    direction = np.einsum("bij,bj->bi", W, sk.tails - sk.heads)
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    spinal = set(_between(sk.parents, trunk[0], trunk[1]))
    if "head" in roles:
        spinal |= set(_between(sk.parents, trunk[1], roles["head"]))
    partner = {roles[f"{seg}.{s}"]: roles[f"{seg}.{o}"] for seg in LIMB_SEGMENTS for s, o in (("L", "R"), ("R", "L"))
               if f"{seg}.{s}" in roles and f"{seg}.{o}" in roles}
    ends = {roles[f"{seg}.{x}"] for seg in END_SEGMENTS for x in "LR" if f"{seg}.{x}" in roles}
    local = np.einsum("bji,bjk->bik", W[sk.parents[1:]], W[1:])            # world-axes joint rotations
    new = np.empty_like(W)
    for b in range(sk.num_bones):
        new[b] = W[b] if b == 0 else new[sk.parents[b]] @ local[b - 1]
        if b in spinal:
            new[b] = rotvec_to_matrix(np.pi * direction[b]) @ W[b]
        elif b in ends:
            new[b] = new[sk.parents[b]]
        elif b in partner:
            aim = turn_between(new[b] @ (sk.tails[b] - sk.heads[b]), direction[partner[b]])
            new[b] = rotvec_to_matrix(aim) @ new[b]
    rel = np.concatenate([new[:1], np.einsum("bji,bjk->bik", new[sk.parents[1:]], new[1:])])
    rotations = matrix_to_quat(np.swapaxes(sk.frames, 1, 2) @ rel @ sk.frames)[None]
    return Poses(rotations, pose.translations.copy(), pose.scales.copy())


def _between(parents, a, b) -> list:
    """Bones on the chain between bones ``a`` and ``b`` (both included; one must be above the other)."""
    up = [b]
    while up[-1] != a and up[-1] > 0:
        up.append(parents[up[-1]])
    if up[-1] == a:
        return up
    down = [a]
    while down[-1] != b and down[-1] > 0:
        down.append(parents[down[-1]])
    return down if down[-1] == b else [a, b]
