"""Which bone of a rig plays which role (:mod:`.vocabulary`), from the bones' names alone.

Every naming the project meets is a preset (:mod:`.presets`): MPFB/MakeHuman ``default``, ``cmu_mb``
(= CMU BVH, MotionBuilder names) and ``game_engine`` (= Unreal) rigs, CMU BVH with 3ds-Max names, Mixamo,
Rigify's DEF-, ORG- and FK-control bones, and Articula's role names (rigs Articula builds or learns).
Names are compared by their key (:func:`name_key`): no namespace (``mixamorig:``, ``Armature|``), lower
case, the side in any convention (``.L``, ``_l``, ``-R``, ``Left``/``Right``/``L``/``R`` prefixes,
Rigify's ``.L.001``) written ``.L``/``.R``: ``LeftUpLeg``, ``UpLeg.L`` and ``mixamorig:LeftUpLeg`` are one.

A rig's naming is the preset covering the largest share of the core roles it names (ties: the preset's
priority, then the number of roles found); a rig no preset covers to :data:`MINIMUM` gets the roles of
the bones whose key means one role in every preset that has it (a lone ``LeftUpLeg``, a few role-named
bones).  Topology and geometry (rigs with meaningless names) are :mod:`solver.retarget.humanoid`'s.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

from .presets import RigPreset, builtin_presets, coverage
from .vocabulary import ROLES

MINIMUM = 0.6           # share of a preset's core roles a rig must have to be named by that preset
NAME_PREFIX = "name:"   # bone_keys of bones without a role
_NAMESPACE = re.compile(r"^.*[:|]")
_SUFFIX = re.compile(r"^(?P<base>.+?)[._-](?P<side>[LRlr])(?P<number>\.\d+)?$")
_PREFIX = re.compile(r"^(?:(?P<word>Left|Right)_?|(?P<letter>[LR])(?=[A-Z]))(?P<base>.+)$")


@dataclass(frozen=True)
class Recognition:
    """``roles {role: bone index}`` (vocabulary order) and the ``preset`` that named them (None: no
    preset fitted, the roles come from unambiguous names)."""
    roles: dict
    preset: RigPreset | None = None


def name_key(name: str) -> str:
    """``name`` compared across namings: no namespace, lower case, ``.L``/``.R`` for the side."""
    base = _NAMESPACE.sub("", str(name))
    side, number = "", ""
    m = _SUFFIX.match(base)
    if m:
        base, side, number = m.group("base"), m.group("side").upper(), m.group("number") or ""
    else:
        m = _PREFIX.match(base)
        if m:
            side, base = (m.group("word") or m.group("letter"))[0], m.group("base")
    key = base.lower() + number
    return f"{key}.{side}" if side else key


@lru_cache(maxsize=1)
def _namings():
    """``[(preset, {key: role})]`` of the built-in presets, and ``{key: role}`` of the keys that mean
    the same role in every preset that has them."""
    out, seen = [], {}
    for preset in builtin_presets():
        keys = {name_key(bone): role for role, bone in preset.roles.items()}
        out.append((preset, keys))
        for key, role in keys.items():
            seen.setdefault(key, set()).add(role)
    return out, {key: roles.pop() for key, roles in seen.items() if len(roles) == 1}


ROLE_NAMING = "articula"    # the preset whose names are the roles themselves (learned and Articula rigs)


def recognise(names, minimum: float = MINIMUM) -> Recognition:
    """The roles of the bones called ``names`` (see the module docstring)."""
    index = {}
    for b, name in enumerate(names):
        index.setdefault(name_key(name), b)
    namings, unambiguous = _namings()
    best, best_found, best_rank = None, {}, (minimum - 1e-9, 0, 0)
    for preset, keys in namings:
        found = {role: index[key] for key, role in keys.items() if key in index}
        rank = (coverage(preset, found), preset.priority if found else 0, len(found))
        if rank > best_rank:
            best, best_found, best_rank = preset, found, rank
    taken = set(best_found.values())
    fill = best is None or best.name == ROLE_NAMING
    for key, b in index.items():           # roles a role-named rig leaves out, by names only one role has
        role = unambiguous.get(key) if fill else None     # anywhere (its root called Unreal's "pelvis")
        if role is not None and role not in best_found and b not in taken:
            best_found[role] = b
            taken.add(b)
    return Recognition({r: best_found[r] for r in ROLES if r in best_found}, best)


def role_bones(names) -> dict:
    """``{role: bone index}`` of the bones called ``names``."""
    return recognise(names).roles


def bone_roles(names) -> list:
    """The role of each bone called ``names`` (None for bones that play none)."""
    out = [None] * len(names)
    for role, b in role_bones(names).items():
        out[b] = role
    return out


def bone_keys(names, parents=None) -> list:
    """Per bone the key under which another rig's data is looked up (the generic pose prior, start poses):
    its role; else, with ``parents`` (B,) given, ``"<role>+k"`` for the k-th bone of a single-child chain
    below a role bone (CMU's ``Spine`` and Unreal's ``spine_02`` are both ``spine+1``, ``Neck1`` and
    MakeHuman's ``neck02`` ``neck+1``); else ``"name:" + name_key``.  So a role-named learned rig and an
    MPFB rig meet on their roles."""
    roles = bone_roles(names)
    out = [role or NAME_PREFIX + name_key(n) for role, n in zip(roles, names)]
    if parents is None:
        return out
    parents = [int(p) for p in parents]
    children = [0] * len(parents)
    for p in parents:
        if p >= 0:
            children[p] += 1
    for b, role in enumerate(roles):
        k, up = 1, parents[b]
        while role is None and up >= 0 and children[up] == 1:
            if roles[up] is not None:
                out[b] = f"{roles[up]}+{k}"
                break
            k, up = k + 1, parents[up]
    return out
