"""Anatomical role of a rig bone, from its ``.L``/``.R`` name (see :mod:`.mpfb_rig`), and the joint
limits used by the pose generators.

Roles cover the four MPFB2 rigs (cmu_mb, game_engine, default, mixamo): ``root`` (bone 0), ``spine``,
``neck``, ``head``, ``clavicle``, ``upper_arm``, ``forearm``, ``wrist``, ``finger``, ``hip_girdle``,
``hip``, ``knee``, ``ankle``, ``toe``, ``twist_arm`` / ``twist_leg`` (the default rig's second segments
``upperarm02``/``lowerarm02``/``upperleg02``/``lowerleg02``) and ``other`` (face, eyes, tongue,
breasts: kept at rest).

Limits per role (:data:`LIMITS`, degrees): ``cone`` = largest swing angle (rotation of the bone's Y axis,
about an axis in the local XZ plane), ``twist`` = largest |rotation about local Y|, and for hinges
``hinge`` = (min, max) flexion about the hinge axis (the swing is then only about that axis).  Hinge
axes are defined anatomically, not by the rig's roll: the distal bone flexes towards :data:`FLEX_DIRECTION`
(world, Z up, character facing -Y): the forearm forward (-Y), the lower leg backward (+Y).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

_ROLE_PATTERNS = (
    ("twist_arm", r"^(upperarm02|lowerarm02)"),
    ("twist_leg", r"^(upperleg02|lowerleg02)"),
    ("finger", r"finger|thumb|index|middle|ring|pinky|metacarpal"),
    ("toe", r"toe|ball"),
    ("forearm", r"^(forearm|lowerarm)"),
    ("knee", r"^(leg|calf|lowerleg)"),
    ("upper_arm", r"^(arm|upperarm)"),
    ("hip", r"^(upleg|thigh|upperleg)"),
    ("hip_girdle", r"^(hipjoint|pelvis\.)"),
    ("clavicle", r"^(shoulder|clavicle)"),
    ("wrist", r"^(hand|wrist)"),
    ("ankle", r"^foot"),
    ("neck", r"^neck"),
    ("head", r"^head$"),
    ("spine", r"^(spine|lowerback|hips$|pelvis$)"),
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
    "upper_arm": Limit(75, 40), "forearm": Limit(0, 40, (0, 130)), "wrist": Limit(45, 10),
    "finger": Limit(20, 5), "twist_arm": Limit(0, 30),
    "hip_girdle": Limit(5, 3), "hip": Limit(55, 30), "knee": Limit(0, 5, (0, 120)),
    "ankle": Limit(30, 10), "toe": Limit(20, 0), "twist_leg": Limit(0, 15),
}

#: World direction the distal segment moves to when a hinge flexes.
FLEX_DIRECTION = {"forearm": np.array([0.0, -1.0, 0.0]), "knee": np.array([0.0, 1.0, 0.0])}


def bone_role(name: str, index: int | None = None) -> str:
    """Role of a bone called ``name`` (``.L``/``.R`` form); bone ``index`` 0 is always ``root``."""
    if index == 0:
        return "root"
    base = re.sub(r"\.[LR]$", "", name).lower()
    for role, pattern in _ROLE_PATTERNS:
        if re.search(pattern, base):
            return role
    return "other"


def skeleton_roles(names) -> list:
    """Roles of all bones of a skeleton (bone 0 = root)."""
    return [bone_role(n, i) for i, n in enumerate(names)]


def hinge_axes_local(frames: np.ndarray, roles) -> np.ndarray:
    """(B, 3) unit hinge axes in bone-local coordinates (zero rows for non-hinge bones).

    The axis k = Y x d (d = :data:`FLEX_DIRECTION` of the role, made orthogonal to Y), so a positive
    rotation about k moves the bone's tail towards d.  frames (B, 3, 3) columns = local axes in world.
    """
    axes = np.zeros((len(roles), 3))
    for b, role in enumerate(roles):
        if LIMITS[role].hinge is None:
            continue
        y = frames[b][:, 1]
        d = FLEX_DIRECTION[role] - np.dot(FLEX_DIRECTION[role], y) * y
        k = np.cross(y, d / np.linalg.norm(d))
        axes[b] = frames[b].T @ (k / np.linalg.norm(k))
    return axes
