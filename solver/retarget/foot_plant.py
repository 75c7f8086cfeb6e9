"""Foot-contact clean-up: feet that rest on the ground in the source stay planted on the target.

Contacts are found on the source: the ankle (head of the ``foot`` role) is within ``HEIGHT`` leg lengths
of its lowest height in the clip and its horizontal speed (central differences of the path smoothed over
0.05 s) is below ``SPEED`` leg lengths per second, for at least ``MIN_FRAMES`` frames.  Over a contact the target's ankle is pinned to its mean position during the
contact (blended in and out over ``BLEND`` frames), and the thigh and shin are re-aimed by two-bone
inverse kinematics that keeps the knee in its current bending plane; the foot keeps its world
orientation.  Sliding is measured as the horizontal path length of the ankle during a contact.
"""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import rotation_between
from . import root_motion
from .directions import unit
from .root_motion import moving_average
from .armature import ArmatureRest, forward, local_matrices, world_pose
from ..roles import LEG_ROLES

HEIGHT = 0.06
SPEED = 0.25
MIN_FRAMES = 3
BLEND = 4


def contacts(ankle: np.ndarray, leg: float, fps: float) -> list:
    """``[(first, last)]`` frame ranges (inclusive) where ankle ``(F, 3)`` rests on the ground."""
    z = ankle[:, 2]
    speed = np.zeros(len(ankle))
    if len(ankle) > 2:
        smooth = moving_average(ankle[:, :2], round(0.05 * fps))       # capture noise at high frame rates
        speed = np.linalg.norm(np.gradient(smooth, axis=0), axis=1) * fps
    on = (z - np.percentile(z, 2) < HEIGHT * leg) & (speed < SPEED * leg)
    out, start = [], None
    for f, flag in enumerate(np.append(on, False)):
        if flag and start is None:
            start = f
        elif not flag and start is not None:
            if f - start >= MIN_FRAMES:
                out.append((start, f - 1))
            start = None
    return out


def sliding(ankle: np.ndarray, ranges) -> float:
    """Mean over ``ranges`` of the ankle's horizontal path length during the contact (world units)."""
    if not ranges:
        return 0.0
    return float(np.mean([np.linalg.norm(np.diff(ankle[a:b + 1, :2], axis=0), axis=1).sum() for a, b in ranges]))


def _pins(ankle: np.ndarray, ranges):
    """Per-frame blend weight ``(F,)`` and pinned ankle ``(F, 3)``."""
    F = len(ankle)
    weight, pin = np.zeros(F), ankle.copy()
    for a, b in ranges:
        anchor = ankle[a:b + 1].mean(axis=0)
        lo, hi = max(0, a - BLEND), min(F - 1, b + BLEND)
        for f in range(lo, hi + 1):
            w = 1.0 if a <= f <= b else 1.0 - (a - f if f < a else f - b) / (BLEND + 1)
            if w > weight[f]:
                weight[f], pin[f] = w, anchor
    return weight, pin


def _two_bone(hip, knee, ankle, goal):
    """World rotations ``(F, 3, 3)`` of thigh and shin that take the ankle to ``goal``, knee plane kept."""
    l1 = np.linalg.norm(knee - hip, axis=1)
    l2 = np.linalg.norm(ankle - knee, axis=1)
    to = goal - hip
    d = np.clip(np.linalg.norm(to, axis=1), np.abs(l1 - l2) + 1e-9, (l1 + l2) * 0.9999)
    u = to / np.maximum(np.linalg.norm(to, axis=1), 1e-12)[:, None]
    v = (knee - hip) - np.einsum("fi,fi->f", knee - hip, u)[:, None] * u
    v /= np.maximum(np.linalg.norm(v, axis=1), 1e-12)[:, None]
    a = (l1 ** 2 - l2 ** 2 + d ** 2) / (2 * d)
    h = np.sqrt(np.maximum(l1 ** 2 - a ** 2, 0.0))
    new_knee = hip + a[:, None] * u + h[:, None] * v
    new_ankle = hip + d[:, None] * u
    R1 = rotation_between(unit(knee - hip), unit(new_knee - hip))
    moved = np.einsum("fij,fj->fi", R1, ankle - knee)
    R2 = rotation_between(unit(moved), unit(new_ankle - new_knee))
    return R1, R2


def plant_feet(source: ArmatureRest, target: ArmatureRest, pairs: dict, src_heads, local, want, fps):
    """(local rotations ``(F, Jt, 3, 3)``, report) with the feet planted; the hips keep the path
    ``want (F, 3)``."""
    hips = target.index[pairs["hips"][1]]
    bone = root_motion.translation_bone(target, hips, [target.index[t] for _, t in pairs.values()])
    src_leg = root_motion.leg_length(source, {r: s for r, (s, _) in pairs.items()})
    local = local.copy()
    report = {}
    for side, (thigh, shin, foot) in LEG_ROLES.items():
        ranges = contacts(src_heads[:, source.index[pairs[foot][0]]], src_leg, fps)
        t_thigh, t_shin, t_foot = (target.index[pairs[r][1]] for r in (thigh, shin, foot))
        W, P = _target_world(target, local, hips, bone, want)
        before = sliding(P[:, t_foot], ranges)
        weight, pin = _pins(P[:, t_foot], ranges)
        goal = P[:, t_foot] + weight[:, None] * (pin - P[:, t_foot])
        R1, R2 = _two_bone(P[:, t_thigh], P[:, t_shin], P[:, t_foot], goal)
        _apply(target, local, W, (t_thigh, t_shin, t_foot), R1, R2, weight > 0)
        _, P = _target_world(target, local, hips, bone, want)
        report[side] = {"contacts": len(ranges), "frames": int(sum(b - a + 1 for a, b in ranges)),
                        "sliding_before": before, "sliding_after": sliding(P[:, t_foot], ranges)}
    return local, report


def _target_world(target, local, hips, bone, want):
    loc = np.zeros(local.shape[:2] + (3,))
    loc[:, bone] = root_motion.root_locations(target, local, hips, bone, want)
    W, P = world_pose(target, forward(target, local_matrices(local, loc)))
    return W, P


def _apply(target, local, W, bones, R1, R2, active):
    """Rewrite the local rotations of thigh, shin and foot on the ``active`` frames."""
    thigh, shin, foot = bones
    rel = lambda b: W[:, target.parents[b]] if target.parents[b] >= 0 else None  # noqa: E731
    f = active
    for b, R_parent, R_self in ((thigh, None, R1), (shin, R1, R2 @ R1), (foot, R2 @ R1, None)):
        Wp = rel(b)
        if Wp is None:
            continue
        new_parent = Wp[f] if R_parent is None else R_parent[f] @ Wp[f]
        new_world = W[f, b] if R_self is None else R_self[f] @ W[f, b]
        rest = target.rest[target.parents[b], :3, :3].T @ target.rest[b, :3, :3]
        local[f, b] = np.swapaxes(new_parent @ rest, -1, -2) @ new_world
