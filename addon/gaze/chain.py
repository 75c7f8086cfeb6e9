"""Which bones turn a rig's gaze and where its face points.

Chest, neck and head are found by role (:func:`solver.retarget.mapping.auto_roles`: the bone names
through the role vocabulary :mod:`solver.roles` — Articula, MakeHuman/MPFB, Rigify, Mixamo, CMU and Unreal
names — then the skeleton's shape), each overridable by name.  The gaze line: on an Articula rig whose mesh has the MakeHuman body topology, from
the annotated back of the head through the point between the eyes (``solver/gaze/data``); otherwise from
the midpoint of the eye bones (or the middle of the head bone) along the rest pose's facing: horizontal
(perpendicular to the armature's up axis), left × up, so Blender's −Y for a character built facing −Y
however stooped or leaning its rest pose is.  Eye bones (``eye``/``Eye`` in the name, below
the head, not driven by constraints) converge on the target.
"""
import json
import os
import re

import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.gaze.aim import GazeChain
from ...solver.retarget.armature import rest_world
from ...solver.retarget.mapping import auto_roles
from ...solver.roles import CENTRE
from ..retarget.armatures import constrained_bones, driven_bones
from ..rig import reader as rig_reader

ROLES = CENTRE[2:]                  # chest, neck, head
SHARES = (0.1, 0.4, 0.5)
MAX_DEG = (25.0, 50.0, 60.0)        # chest, neck, head: each joint's largest turn
_ANNOTATION = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                           "solver", "gaze", "data", "makehuman_body.json")
_EYE = re.compile(r"(^|[^a-z])eye([^a-z]|$)|eye[._ -]?[lr]$|^(left|right)eye", re.IGNORECASE)


def find_bones(arm_ob, rest, found: dict, overrides=None) -> dict:
    """``{role: bone index}`` of chest, neck and head from the roles ``found`` (``{role: bone name}``) and
    ``overrides`` (``{role: bone name}``, '' = as found)."""
    overrides = overrides or {}
    out = {}
    for role in ROLES:
        name = overrides.get(role) or found.get(role)
        if name:
            if name not in rest.index:
                raise ArticulaInputError(f"{arm_ob.name!r} has no bone {name!r} (the {role} bone)")
            out[role] = rest.index[name]
    if "head" not in out:
        raise ArticulaInputError(f"no head bone found on {arm_ob.name!r}: name it in the Gaze panel (Head Bone)")
    busy = set(constrained_bones(arm_ob, {rest.bones[b] for b in out.values()})) | \
        ({rest.bones[b] for b in out.values()} & set(driven_bones(arm_ob)))
    if busy:
        raise ArticulaInputError(f"bones {', '.join(sorted(busy))} of {arm_ob.name!r} have constraints or drivers "
                                 "that would override the gaze turn")
    return out


def eye_bones(arm_ob, rest, head: int) -> list:
    """Indices of the eye bones below ``head`` that nothing else drives."""
    below = [b for b, name in enumerate(rest.bones) if b != head and rest.is_ancestor(head, b)
             and _EYE.search(name) and not name.startswith(("MCH-", "ORG-", "DEF-"))]
    busy = set(constrained_bones(arm_ob, {rest.bones[b] for b in below})) | set(driven_bones(arm_ob))
    return [b for b in below if rest.bones[b] not in busy]


def _up(heads: np.ndarray, roles: dict) -> np.ndarray:
    """The armature axis (unit, signed) nearest the hips-to-head line of rest joint positions ``heads`` (B,3)."""
    body = heads[roles["head"]] - heads[roles.get("hips", roles.get("chest", roles["head"]))]
    up = np.zeros(3)
    if np.linalg.norm(body) < 1e-9:
        up[2] = 1.0
        return up
    axis = int(np.argmax(np.abs(body)))
    up[axis] = np.sign(body[axis])
    return up


def _level(direction: np.ndarray, up: np.ndarray):
    """``direction`` with its component along ``up`` removed, unit length; None when it is (nearly) vertical."""
    flat = direction - up * (direction @ up)
    n = np.linalg.norm(flat)
    return flat / n if n > 1e-6 else None


def _facing(rest, roles: dict) -> np.ndarray:
    """Unit forward direction (armature space) of an upright character's rest pose: horizontal, i.e.
    ``left × up`` with ``up`` the armature axis nearest the hips-to-head line and ``left`` (thighs, upper
    arms or shoulders) made perpendicular to it, so a stooped or leaning rest does not tilt it; −Y (Blender's
    front) when these bones are missing."""
    _, heads = rest_world(rest)
    heads = rest.armature_points(heads)
    up = _up(heads, roles)
    for a, b in (("thigh.L", "thigh.R"), ("upper_arm.L", "upper_arm.R"), ("shoulder.L", "shoulder.R")):
        if a in roles and b in roles:
            left = _level(heads[roles[a]] - heads[roles[b]], up)
            if left is not None:
                return np.cross(left, up)
    return np.array([0.0, -1.0, 0.0])


def _level_line(line, rest, roles: dict):
    """The annotated gaze line with its direction made level (perpendicular to the rest's up): the
    nasion-to-occiput axis pitches down by a few degrees, more on a stooped body, and the rest facing of an
    upright character is horizontal."""
    _, heads = rest_world(rest)
    forward = _level(line[1], _up(rest.armature_points(heads), roles))
    return line[0], (line[1] if forward is None else forward)


def _annotated_line(arm_ob, rest):
    """(origin, direction) in armature space from the MakeHuman-topology annotation, or None."""
    if arm_ob.articula.kind != 'RIG_ARMATURE':
        return None
    mesh = rig_reader.find_mesh(arm_ob)
    with open(_ANNOTATION, encoding="utf-8") as fh:
        note = json.load(fh)
    if mesh is None or len(mesh.data.vertices) != note["vertex_count"]:
        return None
    co = np.empty(3 * len(mesh.data.vertices))
    mesh.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ np.array(mesh.matrix_world)[:3, :3].T + np.array(mesh.matrix_world)[:3, 3]
    co = rest.armature_points(co)
    front, back = co[note["front"]].mean(axis=0), co[note["back"]].mean(axis=0)
    return front, (front - back) / np.linalg.norm(front - back)


FACINGS = {"-Y": (0.0, -1.0, 0.0), "+Y": (0.0, 1.0, 0.0), "-X": (-1.0, 0.0, 0.0), "+X": (1.0, 0.0, 0.0)}


def gaze_chain(arm_ob, rest, overrides=None, shares=SHARES, max_deg=MAX_DEG, facing: str = ""):
    """``(GazeChain, eyes [(bone, direction)], how)`` of armature object ``arm_ob``; ``facing`` ('-Y', '+Y',
    '-X', '+X' in the armature's rest axes; '' = automatic) overrides where the face points."""
    found = auto_roles(rest).roles
    roles = find_bones(arm_ob, rest, found, overrides)
    all_roles = {r: rest.index[b] for r, b in found.items()}
    all_roles.update(roles)
    joints = [roles[r] for r in ROLES if r in roles]
    s = np.array([sh for r, sh in zip(ROLES, shares) if r in roles], dtype=np.float64)
    if s.sum() <= 0:
        raise ArticulaInputError("gaze: the shares of the found joints are all zero")
    head = roles["head"]
    R = rest.rest[head, :3, :3]
    eyes = eye_bones(arm_ob, rest, head)
    line = None if facing else _annotated_line(arm_ob, rest)
    if facing:
        if facing not in FACINGS:
            raise ArticulaInputError(f"gaze: unknown facing {facing!r} (choose from {', '.join(FACINGS)})")
        forward = np.array(FACINGS[facing])
        origin = rest.rest[eyes, :3, 3].mean(axis=0) if eyes else (rest.rest[head, :3, 3] + rest.tails[head]) / 2
        how = f"facing {facing} (set by hand)"
    elif line is not None:
        (origin, forward), how = _level_line(line, rest, all_roles), "annotated MakeHuman eyes, level"
    else:
        forward = _facing(rest, all_roles)
        if eyes:
            origin, how = rest.rest[eyes, :3, 3].mean(axis=0), "eye bones, rest facing"
        else:
            origin, how = (rest.rest[head, :3, 3] + rest.tails[head]) / 2, "middle of the head bone, rest facing"
    chain = GazeChain(joints, s / s.sum(), head, R.T @ (origin - rest.rest[head, :3, 3]), R.T @ forward,
                      np.radians([d for r, d in zip(ROLES, max_deg) if r in roles]))
    eye_dirs = [(b, rest.rest[b, :3, :3].T @ forward) for b in eyes]
    return chain, eye_dirs, how
