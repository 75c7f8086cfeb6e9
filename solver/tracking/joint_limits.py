"""Joints of a posed body measured against their limits, for the truth-free checks
(:mod:`solver.tracking.checks`): the knees and elbows as hinges with a flexion axis fixed to the upper
segment, and the trunk's twist and backward bend between the hips and the chest, all from the bone roles
of any rig.  Rest quantities are found once per model (:func:`hinges_of`, :func:`trunk_of`); the angles of
a pose come from its part maps ``Rm (B, 3, 3)`` (scale included, removed here) and ``tm (B, 3)``.
Degrees out, metres in.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..geometry.rotations import matrix_to_quat

HINGE_AXIS_DEG = 10.0   # a rest bend above this gives the hinge axis (the bones' plane), else the feet's forward
HINGE_BENT_DEG = 25.0   # ... and above this the axis is sure enough for a sideways bend (joints 1-2 cm off
                        # turn it by < 5 deg; at 10 deg by up to ~20 deg, which keeps a flexion's sign)


@dataclasses.dataclass
class Hinge:
    """A knee or elbow: three joints as ``(bone, rest point)`` (posed by that bone's map), the bone whose
    map carries the rest flexion ``axis`` (3,) (positive rotation about it bends the joint), and whether
    the axis is sure enough to measure a ``sideways`` bend (it came from the rest bend)."""
    name: str
    kind: str
    points: tuple
    axis_bone: int
    axis: np.ndarray
    sideways: bool


def trunk_of(sk, roles, toes):
    """``(hips bone, chest bone, spine (3,), forward (3,) or None)``: the bones whose relative twist and
    bend are checked, the spine's unit rest direction between their joints and the body's rest forward
    (where the feet point, ``toes``: :func:`foot_forwards`, normal to the spine); None without both roles on
    different bones apart."""
    if "hips" not in roles or "chest" not in roles or roles["hips"] == roles["chest"]:
        return None
    axis = sk.heads[roles["chest"]] - sk.heads[roles["hips"]]
    length = float(np.linalg.norm(axis))
    if length < 1e-6:
        return None
    axis = axis / length
    forward = sum(toes.values(), np.zeros(3))
    forward = forward - (forward @ axis) * axis
    size = float(np.linalg.norm(forward))
    return roles["hips"], roles["chest"], axis, (forward / size if size > 0.3 else None)


def joint_at(sk, roles, role, fallback_tail_of=None):
    """``(bone, rest point)`` of the joint at the head of ``role``'s bone, else the tail of the
    ``fallback_tail_of`` role's bone, else None."""
    if role in roles:
        return roles[role], sk.heads[roles[role]]
    if fallback_tail_of in roles:
        return roles[fallback_tail_of], sk.tails[roles[fallback_tail_of]]
    return None


def foot_forwards(model, roles, vertex_region, regions):
    """``{side: unit (3,)}``: where each foot points at rest, from the ankle to the vertex of the lower leg
    or foot beyond the ankle farthest from the lower leg's line, across that line (toes reach farther
    forward than the heel backward; a learned foot bone's tail may point anywhere, and a learned lower leg
    part may hold most of the foot)."""
    sk, out = model.skeleton, {}
    for s in "LR":
        ankle, knee = joint_at(sk, roles, f"foot.{s}", f"shin.{s}"), joint_at(sk, roles, f"shin.{s}")
        if ankle is None or knee is None:
            continue
        shin = (ankle[1] - knee[1]) / np.linalg.norm(ankle[1] - knee[1])
        leg = [regions.index(r) for r in (f"shin.{s}", f"foot.{s}") if r in regions]
        d = model.rest_vertices[np.isin(vertex_region, leg)] - ankle[1]
        d = d[d @ shin > 0]
        d -= np.outer(d @ shin, shin)
        if len(d):
            tip = d[np.argmax(np.linalg.norm(d, axis=1))]
            out[s] = tip / max(np.linalg.norm(tip), 1e-12)
    return out


def hinges_of(sk, roles, toes):
    """Knees and elbows with their rest flexion axes, and notes on those that cannot be checked.  The axis
    of a joint bent at rest (``HINGE_AXIS_DEG``) is normal to its two segments (a rest pose does not bend a
    knee or elbow backwards that far); a straight knee flexes away from its foot's toes (``toes``:
    :func:`foot_forwards`), a straight elbow towards where the feet point.  Those guesses hold for a limb
    hanging or held out sideways, not for one raised in a learned rig's scanned rest pose, where they made
    a right fit read as bent backwards (docs/track.md "7 Dec, afternoon")."""
    out, notes = [], []
    chains = (("knee", "thigh", "shin", "foot", -1.0), ("elbow", "upper_arm", "forearm", "hand", 1.0))
    for kind, top, mid, end, sign in chains:
        for s in "LR":
            pts = (joint_at(sk, roles, f"{top}.{s}"), joint_at(sk, roles, f"{mid}.{s}"),
                   joint_at(sk, roles, f"{end}.{s}", f"{mid}.{s}"))
            name = ("left " if s == "L" else "right ") + kind
            if any(p is None for p in pts):
                notes.append(f"{name}: no {top}/{mid} roles")
                continue
            t, u = pts[1][1] - pts[0][1], pts[2][1] - pts[1][1]
            t, u = t / np.linalg.norm(t), u / np.linalg.norm(u)
            axis = np.cross(t, u)
            bend = np.degrees(np.arccos(np.clip(t @ u, -1.0, 1.0)))
            bent = bend >= HINGE_BENT_DEG
            if bend < HINGE_AXIS_DEG:
                forward = toes.get(s) if kind == "knee" else sum(toes.values(), np.zeros(3))
                axis = np.cross(t, sign * forward) if forward is not None else np.zeros(3)
                if np.linalg.norm(axis) < 0.3:
                    notes.append(f"{name}: straight at rest and no foot to tell forward")
                    continue
            if not bent:
                state = "straight" if bend < HINGE_AXIS_DEG else f"bent {bend:.0f} deg"
                notes.append(f"{name}: {state} at rest, its sideways bend is not checked")
            out.append(Hinge(name, kind, pts, int(sk.parents[pts[1][0]]), axis / np.linalg.norm(axis), bent))
    return out, notes


def _unit(v):
    return v / max(np.linalg.norm(v), 1e-12)


def hinge_points(hinge: Hinge, Rm, tm) -> list:
    """The hinge's three posed joints ``[(3,)] * 3`` (upper, middle, end) by the part maps ``Rm (B, 3, 3)``,
    ``tm (B, 3)``."""
    return [Rm[b] @ x + tm[b] for b, x in hinge.points]


def hinge_angles(hinge: Hinge, Rm, tm):
    """``(flexion, sideways)`` degrees of a hinge posed by the part maps ``Rm (B, 3, 3)``, ``tm (B, 3)``:
    flexion = angle from the upper to the lower segment about the posed axis (negative: bent backwards),
    sideways = the lower segment's angle out of the hinge plane."""
    p = hinge_points(hinge, Rm, tm)
    upper, lower = _unit(p[1] - p[0]), _unit(p[2] - p[1])
    k = _unit(Rm[hinge.axis_bone] @ hinge.axis)
    side = np.degrees(np.arcsin(np.clip(lower @ k, -1.0, 1.0)))
    planar = lower - (lower @ k) * k
    flexion = np.degrees(np.arctan2(np.cross(upper, planar) @ k, upper @ planar))
    return float(flexion), float(side)


def trunk_twist(trunk, Rm) -> float:
    """Degrees the hips bone is turned from the chest bone about the spine's rest direction (the twist of
    their relative rotation's swing-twist split), from the part maps ``Rm (B, 3, 3)`` (scale removed)."""
    hips, chest, axis, _ = trunk
    rel = Rm[chest].T @ Rm[hips]
    return float(np.degrees(abs(signed_twist(rel / np.cbrt(np.linalg.det(rel)), axis))))


def signed_twist(rel, axis) -> float:
    """Radians of the twist about unit ``axis`` in the swing-twist split ``rel = swing @ twist`` of the
    rotation matrix ``rel`` (3, 3), in (-pi, pi]."""
    q = matrix_to_quat(rel)
    return float(2.0 * np.arctan2(q[1:] @ axis, q[0]))


def trunk_back(trunk, Rm):
    """Degrees the chest is bent backwards from the hips (negative: forwards), in the plane of the spine's
    rest direction and the rest forward, from the part maps ``Rm (B, 3, 3)``; None without a forward."""
    hips, chest, axis, forward = trunk
    if forward is None:
        return None
    spine = np.linalg.solve(Rm[hips], Rm[chest] @ axis)         # the posed spine as the hips see it
    return float(np.degrees(np.arctan2(-(spine @ forward), spine @ axis)))
