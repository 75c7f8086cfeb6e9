"""Joint class of a rig bone, from the bone-role vocabulary (:mod:`solver.roles`), and the joint limits
used by the pose generators.

Classes (the keys of :data:`LIMITS`): ``root`` (bone 0); for the bones that play a role, the class of the
role (:data:`ROLE_CLASS`: ``spine`` for hips/spine/chest below the root, ``neck``, ``head``, ``clavicle``,
``upper_arm``, ``forearm``, ``wrist``, ``finger``, ``hip_girdle``, ``hip``, ``knee``, ``ankle``, ``toe``);
for the other bones of the four MPFB2 rigs (cmu_mb, game_engine, default, mixamo), which the vocabulary
does not name, the chain they extend (:data:`_EXTRA_PATTERNS`): further spine, neck, clavicle, toe and
finger bones, ``twist_arm`` / ``twist_leg`` (the default rig's second segments ``upperarm02``/
``lowerarm02``/``upperleg02``/``lowerleg02``), and ``other`` (face, eyes, tongue, breasts: kept at rest).

Limits per class (:data:`LIMITS`, degrees): ``cone`` = largest swing angle (rotation of the bone's Y axis,
about an axis in the local XZ plane), ``twist`` = largest |rotation about local Y|, and for hinges
``hinge`` = (min, max) *anatomical* flexion (angle between the two segments, 0 = straight) about the
hinge axis; the swing is then only about that axis.  Hinge axes are defined anatomically, not by the
rig's roll (:func:`hinge_geometry`): in the plane of the two bones when the rest pose is bent (the
elbows of MakeHuman's A-pose), otherwise towards :data:`FLEX_DIRECTION` (world, Z up, character facing
-Y: the lower leg bends backward, +Y).

Major joints (:func:`major_joints`): the 14 joints of tracking benchmarks (shoulders, elbows, wrists,
hips, knees, ankles, neck, head) as bone heads of any of the four rigs.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.roles import FINGERS, bone_roles

#: Class of each role of the vocabulary (without side and finger segment).
ROLE_CLASS = {"hips": "spine", "spine": "spine", "chest": "spine", "neck": "neck", "head": "head",
              "shoulder": "clavicle", "upper_arm": "upper_arm", "forearm": "forearm", "hand": "wrist",
              "hip": "hip_girdle", "thigh": "hip", "shin": "knee", "foot": "ankle", "toe": "toe",
              **{finger: "finger" for finger in FINGERS}}
#: Classes of the bones no role names (lower-case base name without side), first match wins.
_EXTRA_PATTERNS = (
    ("twist_arm", r"^(upperarm02|lowerarm02)"),
    ("twist_leg", r"^(upperleg02|lowerleg02)"),
    ("finger", r"finger|thumb|index|middle|ring|pinky|metacarpal"),
    ("toe", r"^toe"),
    ("clavicle", r"^shoulder"),
    ("neck", r"^neck"),
    ("spine", r"^spine"),
)


@dataclass(frozen=True)
class Limit:
    """Joint limit in degrees: swing cone, |twist|, optional hinge flexion range (min, max)."""
    cone: float
    twist: float
    hinge: tuple | None = None


LIMITS = {
    "root": Limit(0, 0), "other": Limit(0, 0),
    "spine": Limit(15, 10), "neck": Limit(20, 25), "head": Limit(20, 30), "clavicle": Limit(10, 5),
    "upper_arm": Limit(75, 40), "forearm": Limit(0, 40, (0, 145)), "wrist": Limit(45, 10),
    "finger": Limit(20, 5), "twist_arm": Limit(0, 30),
    "hip_girdle": Limit(5, 3), "hip": Limit(55, 30), "knee": Limit(0, 5, (0, 135)),
    "ankle": Limit(30, 10), "toe": Limit(20, 0), "twist_leg": Limit(0, 15),
}

#: Bend angle (degrees) above which a hinge's flexion plane is taken from its two bones.
BENT_DEG = 15.0
#: World direction the distal segment moves to when a straight hinge flexes.
FLEX_DIRECTION = {"forearm": np.array([0.0, -1.0, 0.0]), "knee": np.array([0.0, 1.0, 0.0])}


def bone_role(name: str, index: int | None = None) -> str:
    """Class of a bone called ``name`` alone (no rig around it: :func:`solver.roles.bone_roles` of the one
    name); bone ``index`` 0 is always ``root``."""
    return _classes([name], [index])[0]


def skeleton_roles(names) -> list:
    """Classes of all bones of a skeleton with these ``names`` (bone 0 = root), their roles recognised
    with the rig's naming."""
    return _classes(list(names), range(len(names)))


def _classes(names, indices) -> list:
    out = []
    for name, index, role in zip(names, indices, bone_roles(names)):
        if index == 0:
            out.append("root")
        elif role is not None:
            out.append(ROLE_CLASS[role.split(".", 1)[0]])
        else:
            base = re.sub(r"\.[LR]$", "", name).lower()
            out.append(next((c for c, pattern in _EXTRA_PATTERNS if re.search(pattern, base)), "other"))
    return out


def hinge_geometry(skeleton, roles) -> tuple[np.ndarray, np.ndarray]:
    """Hinge axes (B, 3) in bone-local coordinates and rest flexion angles (B,) radians.

    Rows of non-hinge bones are zero.  For a hinge bone with direction y and parent direction p:
    if the rest bend angle(p, y) exceeds :data:`BENT_DEG` the flexion plane is the plane of the two
    bones and k = p x y / |.| (the rest flexion is that angle); otherwise (a straight joint, e.g. the
    knee) k = y x d / |.| with d = :data:`FLEX_DIRECTION` made orthogonal to y, and the rest flexion is
    the angle from p to y about k.  A positive rotation about k bends the joint further.
    """
    B = skeleton.num_bones
    axes, rest = np.zeros((B, 3)), np.zeros(B)
    direction = skeleton.tails - skeleton.heads
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    for b, role in enumerate(roles):
        if LIMITS[role].hinge is None:
            continue
        y, p = direction[b], direction[skeleton.parents[b]]
        bend = np.arccos(np.clip(p @ y, -1, 1))
        if bend > np.radians(BENT_DEG):
            k = np.cross(p, y)
        else:
            d = FLEX_DIRECTION[role] - np.dot(FLEX_DIRECTION[role], y) * y
            k = np.cross(y, d)
            bend = np.arctan2(np.cross(p, y) @ (k / np.linalg.norm(k)), p @ y)
        axes[b] = skeleton.frames[b].T @ (k / np.linalg.norm(k))
        rest[b] = bend
    return axes, rest


def hinge_ranges(skeleton, roles) -> np.ndarray:
    """(B, 2) rest-relative flexion ranges in radians: the anatomical ``hinge`` range of the role minus
    the rest flexion (MakeHuman's A-pose already bends the elbows by about 35 degrees); NaN rows for
    non-hinge bones."""
    _, rest = hinge_geometry(skeleton, roles)
    out = np.full((len(roles), 2), np.nan)
    for b, role in enumerate(roles):
        if LIMITS[role].hinge is not None:
            lo, hi = np.radians(LIMITS[role].hinge) - rest[b]
            out[b] = min(lo, 0.0), max(hi, 0.0)          # the rest pose is always allowed
    return out


#: Labels of the major joints (benchmarks of trackers) and the (role, side) of the bone whose head is
#: the joint; side "" = on the midline (the first bone of the role from the root, e.g. the lowest neck bone).
MAJOR_JOINTS = (
    ("shoulder.L", "upper_arm", ".L"), ("shoulder.R", "upper_arm", ".R"),
    ("elbow.L", "forearm", ".L"), ("elbow.R", "forearm", ".R"),
    ("wrist.L", "wrist", ".L"), ("wrist.R", "wrist", ".R"),
    ("hip.L", "hip", ".L"), ("hip.R", "hip", ".R"),
    ("knee.L", "knee", ".L"), ("knee.R", "knee", ".R"),
    ("ankle.L", "ankle", ".L"), ("ankle.R", "ankle", ".R"),
    ("neck", "neck", ""), ("head", "head", ""),
)
MAJOR_JOINT_LABELS = tuple(label for label, _, _ in MAJOR_JOINTS)


def major_joints(skeleton) -> dict:
    """``{label: bone index}`` for the 14 :data:`MAJOR_JOINT_LABELS`, in that order; the joint is the head
    of that bone (shoulder = upper arm, elbow = forearm, wrist = hand, hip = thigh, knee = lower leg,
    ankle = foot, neck = the first neck bone, head = head).  ``skeleton``: a ``Skeleton`` or its bone
    names (``.L``/``.R`` form, parents before children).  MakeHuman's ``.L`` side is at +x (facing -Y)."""
    names = list(getattr(skeleton, "names", skeleton))
    roles = skeleton_roles(names)
    out = {}
    for label, role, side in MAJOR_JOINTS:
        found = [b for b, (n, r) in enumerate(zip(names, roles)) if r == role and (n.endswith(side) if side
                 else not n.endswith((".L", ".R")))]
        if not found:
            where = f"on side {side}" if side else "on the midline"
            raise ArticulaInputError(f"major joints: no bone with the role {role!r} {where} for {label!r} "
                                     f"among the {len(names)} bones of the skeleton")
        out[label] = found[0]
    return out
