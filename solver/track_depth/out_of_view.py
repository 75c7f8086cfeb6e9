"""Body parts out of the camera's view (ours; the dissertation's recordings show the whole body): a part
whose points mostly project outside the image has no data to place it, and the fit would otherwise lay it
over points other parts explain (a leg folded up onto an arm).  A leg (thigh, shin or foot, cut by the
image's bottom edge) out of view is held straight as in the rest pose, which for a standing person puts it
below the hips; whether it is out of view is judged with it straight, so a leg folded into the image is
not taken as seen.  An arm or the head out of view is named but not held: where it is out of view depends
on the fit itself (a start hypothesis's arm may be), and holding it there would keep it from data that
would bring it back.  Parts out of view are named per frame in the report.

Parts are found by bone roles (:mod:`solver.roles`); a rig without them has no parts and nothing is held.
"""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import rotvec_to_quat
from ..roles import role_bones
from ..tracking.limbs import subtrees
from ..tracking.priors import held_at
from .visibility import in_view

PART_ROLES = ("thigh", "shin", "foot", "upper_arm", "forearm", "hand", "head")
STRAIGHT = ("thigh", "shin", "foot")   # held straight (the rest pose's legs) when out of view
OUTSIDE_SHARE = 0.5                    # a part with more of its points outside the image is out of view
MIN_POINTS = 5                         # parts with fewer tracker points are not judged
SIDES = {"L": "left", "R": "right"}
WORDS = {"thigh": "leg", "shin": "lower leg", "upper_arm": "arm"}   # a part names everything below it


def part_name(role: str) -> str:
    """Readable name of a part role: "thigh.L" -> "left leg", "forearm.R" -> "right forearm"."""
    base, _, side = role.partition(".")
    return (SIDES[side] + " " if side in SIDES else "") + WORDS.get(base, base.replace("_", " "))


def _kind(role: str) -> str:
    return role.partition(".")[0]


def _links(parents, b, stops) -> list:
    """The bones from ``b``'s parent up to (without) the first of ``stops`` (a thigh's hip bone, an upper
    arm's clavicle): they swing the part as a whole, so a held part holds them too."""
    out, p = [], parents[b]
    while p >= 0 and p not in stops:
        out.append(int(p))
        p = parents[p]
    return out if p >= 0 else []


class Parts:
    """The parts of a tracking body (:class:`solver.tracking.blend_body.BlendBody`), parents first: ``(role, bone, held bones
    (its subtree and the links to the trunk), its own points (its subtree's without the next part's),
    straight)``."""

    def __init__(self, body):
        sk = body.model.skeleton
        roles = role_bones(sk.names)
        below = subtrees(sk.parents)
        stops = {b for r, b in roles.items() if _kind(r) in PART_ROLES + ("hips", "spine", "chest", "neck")}
        self.parts = []
        for role, b in sorted(((r, b) for r, b in roles.items() if _kind(r) in PART_ROLES), key=lambda item: item[1]):
            inner = [c for r2, c in roles.items() if c != b and c in below[b] and _kind(r2) in PART_ROLES]
            own = set(below[b]) - {x for c in inner for x in below[c]}
            rows = np.flatnonzero(np.isin(body.main_bone, sorted(own)))
            held = np.array(_links(sk.parents, b, stops) + list(below[b]))
            if len(rows) >= MIN_POINTS:
                self.parts.append((role, b, held, rows, _kind(role) in STRAIGHT))

    def out_of_view(self, body, pose, camera) -> tuple:
        """``(names, bones, targets)``: the parts of ``pose`` (one frame) out of view, the bones held (every
        bone of a leg out of view and its links to the trunk) and their bone-local rotation vectors (k, 3)."""
        if not self.parts:
            return [], np.zeros(0, np.int64), np.zeros((0, 3))
        straight = pose.take(slice(None))      # legs straight; arms and head as they are (no leg carries them)
        for role, b, sub, rows, is_straight in self.parts:
            if is_straight:
                straight.rotations[0, sub] = (1.0, 0.0, 0.0, 0.0)
        uv, z = camera.project(body.pose(straight).points)
        outside = ~in_view(uv, z, camera.intr)
        names, held, targets, covered = [], [], [], set()
        for role, b, sub, rows, is_straight in self.parts:
            if b in covered:            # below a part already out of view
                continue
            if outside[rows].mean() > OUTSIDE_SHARE:
                names.append(part_name(role))
                covered.update(sub.tolist())
                if is_straight:
                    held.extend(sub.tolist())
                    targets.append(np.zeros((len(sub), 3)))
        if not held:
            return names, np.zeros(0, np.int64), np.zeros((0, 3))
        return names, np.array(held, np.int64), np.concatenate(targets)

    def hold(self, body, pose, camera, limits) -> tuple:
        """``(bones, pose, limits)``: the bones held (:meth:`out_of_view`), ``pose`` with them set to what
        they are held at, and the prior terms ``limits`` (a list) with a box holding them
        (:func:`solver.tracking.priors.held_at`)."""
        _, bones, targets = self.out_of_view(body, pose, camera)
        if not len(bones):
            return bones, pose, limits
        held = pose.take(slice(None))
        held.rotations[0, bones] = rotvec_to_quat(targets)
        return bones, held, [*limits, held_at(body.num_bones, bones, targets)]
