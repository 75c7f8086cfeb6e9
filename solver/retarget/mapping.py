"""A bone mapping between two rigs: for each role, the source bone and the target bone that play it.

Found automatically (:func:`auto_roles`: the bone names through :func:`solver.roles.recognise`, then the
skeleton's topology and geometry for roles the names lack or for unknown rigs, :mod:`.humanoid`), shown and edited in the
panel, saved and loaded as JSON ``{"format": "articula-retarget-mapping", "version": 1, "rows":
[{"role", "source", "target"}, ...]}``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

from ..errors import ArticulaInputError
from ..roles import CORE, ROLES, ordered, recognise
from . import humanoid
from .armature import subset

FORMAT = "articula-retarget-mapping"
HELPER_PREFIXES = ("SW-", "TW-", "NEUTRAL", "MCH-", "ORG-", "VIS_", "WGT-")   # Articula and Rigify helpers


@dataclass
class RoleFinding:
    """The roles found on one rig and how: ``roles {role: bone}``, ``preset`` label or '' and the roles
    that came from the skeleton's shape (``inferred``)."""
    roles: dict
    preset: str = ""
    inferred: list = field(default_factory=list)


def auto_roles(arm) -> RoleFinding:
    """Roles of armature ``arm`` (:class:`~.armature.ArmatureRest`): from its bone names, completed (or
    replaced, for unknown rigs) by topology/geometry inference on the bones that are not helpers."""
    named = recognise(arm.bones)
    preset, found = named.preset, {role: arm.bones[b] for role, b in named.roles.items()}
    guessed = humanoid.infer_roles(subset(arm, [not b.startswith(HELPER_PREFIXES) for b in arm.bones]))
    roles = dict(found)
    taken = set(roles.values())
    inferred = []
    for role, bone in guessed.items():
        if role not in roles and bone not in taken:
            roles[role], inferred = bone, inferred + [role]
            taken.add(bone)
    return RoleFinding(roles, preset.label if preset else "", ordered(inferred))


@dataclass
class Mapping:
    """``rows``: ``[(role, source bone, target bone)]`` with '' for a side that has no bone."""
    rows: list

    @classmethod
    def from_roles(cls, source: dict, target: dict) -> "Mapping":
        return cls([(r, source.get(r, ""), target.get(r, "")) for r in ROLES if r in source or r in target])

    def pairs(self) -> dict:
        """``{role: (source bone, target bone)}`` of the rows with both bones."""
        return {r: (s, t) for r, s, t in self.rows if s and t}

    def missing(self, roles=CORE) -> list:
        """The ``roles`` with no bone on the source or the target side."""
        have = self.pairs()
        return [r for r in roles if r not in have]

    def check(self, source_bones, target_bones) -> None:
        """Refuse bones the armatures do not have and bones used twice."""
        for side, names, col in (("source", set(source_bones), 1), ("target", set(target_bones), 2)):
            used = [row[col] for row in self.rows if row[col]]
            absent = [b for b in used if b not in names]
            if absent:
                raise ArticulaInputError(f"the mapping names {side} bones the {side} armature does not have: "
                                         + ", ".join(repr(b) for b in absent[:6]))
            twice = sorted({b for b in used if used.count(b) > 1})
            if twice:
                raise ArticulaInputError(f"the mapping uses {side} bone(s) {', '.join(map(repr, twice))} "
                                         "for more than one role")

    def to_json(self) -> str:
        rows = [{"role": r, "source": s, "target": t} for r, s, t in self.rows]
        return json.dumps({"format": FORMAT, "version": 1, "rows": rows}, indent=1)

    @classmethod
    def from_json(cls, text: str, where: str = "mapping") -> "Mapping":
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise ArticulaInputError(f"{where}: not JSON ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ArticulaInputError(f"{where}: not an Articula retarget mapping (expected \"format\": \"{FORMAT}\")")
        rows = []
        for i, row in enumerate(data.get("rows") or []):
            if not isinstance(row, dict) or row.get("role") not in ROLES:
                raise ArticulaInputError(f"{where}: row {i + 1} has no known \"role\"")
            rows.append((row["role"], str(row.get("source") or ""), str(row.get("target") or "")))
        if not rows:
            raise ArticulaInputError(f"{where}: the mapping has no rows")
        return cls(rows)


def describe_missing(missing: list, side: str = "") -> str:
    """A user-facing list of missing roles (``upper_arm.L, forearm.L, …``)."""
    where = f" on the {side}" if side else ""
    return f"no bone{where} for the role(s) {', '.join(missing)}"
