"""Human roles of an unknown rig from its skeleton's topology and rest geometry (no names).

World +Z is up.  Steps: the two feet are the lowest leaves whose common ancestor is well above the
floor (that ancestor is ``hips``); the head is the highest other leaf; the arms end in the two leaves
farthest from the vertical line through the hips on opposite sides, and their common ancestor is
``chest``.  Along each limb path the limb starts at the first joint clearly off the midline (the bone
before it is the girdle, ``shoulder``/``hip``); elbow and wrist, knee and ankle are the joints closest to
the average human segment lengths along the path (Drillis & Contini's proportions of the body height),
which tells twist and helper bones from limb joints in any rest pose (T, A or relaxed).  The
character's left is ``up × forward``, with forward taken from the feet (heel-to-toe), else Blender's −Y.
"""
from __future__ import annotations

import numpy as np

from ..roles import ARM as ARM_ROLE_NAMES, LEG as LEG_ROLE_NAMES
from .armature import rest_world

HIP_LATERAL = 0.03      # hip joints lie at least this far from the midline (fraction of the height)
SHOULDER_LATERAL = 0.06
ARM = (0.186, 0.146)    # upper arm, forearm lengths as fractions of the height (Drillis & Contini)
LEG = (0.245, 0.246, 0)  # thigh, shank; the toe is the bone after the ankle


def _ancestors(parents, b) -> list:
    out = []
    while b >= 0:
        out.append(b)
        b = parents[b]
    return out[::-1]


def _lca(parents, a, b):
    pa, pb = _ancestors(parents, a), _ancestors(parents, b)
    common = -1
    for x, y in zip(pa, pb):
        if x != y:
            break
        common = x
    return common


class _Shape:
    """Rest geometry of the armature in world space, with the height and the midline."""

    def __init__(self, arm):
        self.arm = arm
        self.parents = arm.parents
        _, self.heads = rest_world(arm)
        self.tails = arm.world_points(arm.tails)
        z = np.concatenate([self.heads[:, 2], self.tails[:, 2]])
        self.floor, self.height = float(z.min()), float(max(z.max() - z.min(), 1e-9))
        self.children = arm.children()
        self.leaves = [b for b in range(len(arm.bones)) if not self.children[b]]

    def lateral(self, p, centre) -> float:
        return float(np.linalg.norm((p - centre)[:2]))

    def path(self, top, leaf) -> list:
        """Bones strictly below ``top`` down to ``leaf``."""
        chain = _ancestors(self.parents, leaf)
        return chain[chain.index(top) + 1:] if top in chain else []


def _feet(s: _Shape):
    """(leaf A, leaf B, hips) or None."""
    order = sorted(s.leaves, key=lambda b: s.tails[b, 2])
    if len(order) < 4:
        return None
    a = order[0]
    for b in order[1:]:
        top = _lca(s.parents, a, b)
        if top >= 0 and s.heads[top, 2] > s.floor + 0.3 * s.height:
            return a, b, top
    return None


def _nearest_along(s: _Shape, bones, start: int, length: float) -> int:
    """Index (> ``start``) of the bone in ``bones`` whose head lies closest to ``length`` (fraction of the
    height) from the head of ``bones[start]``; -1 when there is none."""
    if start + 1 >= len(bones):
        return -1
    d = np.array([abs(np.linalg.norm(s.heads[b] - s.heads[bones[start]]) - length * s.height)
                  for b in bones[start + 1:]])
    return start + 1 + int(np.flatnonzero(d <= d.min() + 1e-3 * s.height)[0])


def _limb(s: _Shape, top, leaf, names, centre, lateral, lengths):
    """``{role base: bone}`` along the path from ``top`` to ``leaf``: the limb starts at the first joint at
    least ``lateral`` (fraction of the height) from the midline; the bone before it is the girdle; the
    next joints lie ``lengths`` (fractions of the height) further along."""
    bones = s.path(top, leaf)
    first = next((i for i, b in enumerate(bones) if s.lateral(s.heads[b], centre) >= lateral * s.height), -1)
    if first < 0:
        return {}
    out = {names[0]: bones[0]} if first > 0 else {}
    out[names[1]] = bones[first]
    at = first
    for name, length in zip(names[2:], lengths):
        at = _nearest_along(s, bones, at, length) if length else (at + 1 if at + 1 < len(bones) else -1)
        if at < 0:
            break
        out[name] = bones[at]
    return out


def _forward(s: _Shape, feet) -> np.ndarray:
    d = np.zeros(3)
    for foot in feet:
        if foot is not None:
            d += (s.tails[foot] - s.heads[foot]) * [1, 1, 0]
    n = np.linalg.norm(d)
    return d / n if n > 0.02 * s.height else np.array([0.0, -1.0, 0.0])


def infer_roles(arm) -> dict:
    """``{role: bone name}`` of the roles found on armature ``arm`` (:class:`~.armature.ArmatureRest`);
    empty when the skeleton does not look like a standing humanoid."""
    s = _Shape(arm)
    feet = _feet(s)
    if feet is None:
        return {}
    a, b, hips = feet
    centre = s.heads[hips]
    legs = [_limb(s, hips, leaf, LEG_ROLE_NAMES, centre, HIP_LATERAL, LEG)
            for leaf in (a, b)]
    leg_bones = {x for leg in legs for x in leg.values()}
    in_leg = {leaf for leaf in s.leaves if set(_ancestors(s.parents, leaf)) & leg_bones}
    rest = [leaf for leaf in s.leaves if leaf not in in_leg and hips in _ancestors(s.parents, leaf)]
    if len(rest) < 3:
        return {}
    head_leaf = max(rest, key=lambda x: s.tails[x, 2])
    far = sorted(rest, key=lambda x: -s.lateral(s.tails[x], centre))
    d = far[0]
    side_d = (s.tails[d] - centre)[:2]
    opposite = [x for x in far[1:] if float((s.tails[x] - centre)[:2] @ side_d) < 0]
    if not opposite:
        return {}
    e = opposite[0]
    chest = _lca(s.parents, d, e)
    if chest < 0 or chest not in _ancestors(s.parents, head_leaf):
        return {}
    roles = {"hips": hips, **_torso(s, hips, chest, head_leaf)}
    forward = _forward(s, [leg.get("toe") for leg in legs])
    left = np.cross([0.0, 0.0, 1.0], forward)
    for leg, leaf in zip(legs, (a, b)):
        side = "L" if float((s.tails[leaf] - centre) @ left) > 0 else "R"
        roles.update({f"{k}.{side}": v for k, v in leg.items()})
    chest_centre = s.heads[chest]
    for leaf in (d, e):
        arm_roles = _limb(s, chest, leaf, ARM_ROLE_NAMES, chest_centre,
                          SHOULDER_LATERAL, ARM)
        side = "L" if float((s.tails[leaf] - centre) @ left) > 0 else "R"
        roles.update({f"{k}.{side}": v for k, v in arm_roles.items()})
    return {role: arm.bones[b] for role, b in roles.items()}


def _torso(s: _Shape, hips, chest, head_leaf) -> dict:
    """spine, chest, neck and head bones between ``hips`` and the head leaf."""
    out = {"chest": chest}
    below = s.path(hips, chest)
    if len(below) > 1:
        out["spine"] = below[0]
    above = s.path(chest, head_leaf)
    if not above:
        return out
    if len(above) == 1:
        out["head"] = above[0]
        return out
    out["neck"] = above[0]
    for i, b in enumerate(above[1:], 1):
        if len(s.children[b]) != 1:
            if s.heads[b, 2] > s.floor + 0.95 * s.height and i > 1:
                b = above[i - 1]
            out["head"] = b
            break
    return out
