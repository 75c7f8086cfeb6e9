"""Rig presets: which bone of a known rig family plays which role (:mod:`.vocabulary`).

A preset is a JSON file ``{"format": "articula-rig-preset", "version": 1, "name", "label",
"description", "priority" (optional), "roles": {role: bone name}}``; the built-in ones live in ``presets/`` beside this module
(CMU BVH in both naming styles, Mixamo, Rigify deform, original and FK-control bones, MPFB/MakeHuman
``default``, the Unreal mannequin = MPFB ``game_engine``; MPFB ``cmu_mb`` uses the CMU names).  Articula's
own rigs, learned ones included, name their bones by role, which is the ``articula`` preset.  How a rig's
names are compared with a preset's (namespaces, side conventions): :mod:`.recognise`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ..errors import ArticulaInputError
from .vocabulary import CORE, ROLES

FORMAT = "articula-rig-preset"
_DIR = Path(__file__).with_name("presets")


@dataclass(frozen=True)
class RigPreset:
    name: str
    label: str
    description: str
    roles: dict            # role -> bone name (namespace-free)
    priority: int = 0      # wins ties of coverage (a rig holding two presets' bones, e.g. Rigify)


def parse_preset(data: dict, where: str) -> RigPreset:
    """A :class:`RigPreset` from a decoded JSON object; ``where`` names it in errors."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ArticulaInputError(f"{where}: not an Articula rig preset (expected \"format\": \"{FORMAT}\")")
    roles = data.get("roles")
    if not isinstance(roles, dict) or not roles:
        raise ArticulaInputError(f"{where}: the preset has no \"roles\" table")
    unknown = sorted(set(roles) - set(ROLES))
    if unknown:
        raise ArticulaInputError(f"{where}: unknown roles {', '.join(unknown[:5])} (known: {', '.join(ROLES[:8])}, …)")
    if not all(isinstance(b, str) and b for b in roles.values()):
        raise ArticulaInputError(f"{where}: every role needs a bone name")
    name = str(data.get("name") or Path(where).stem)
    return RigPreset(name, str(data.get("label") or name), str(data.get("description", "")), dict(roles),
                     int(data.get("priority", 0)))


def builtin_presets() -> list:
    """The presets shipped with Articula, the ``articula`` role-name preset first."""
    out = [RigPreset("articula", "Articula (role names)", "Rigs learned or built by Articula",
                     {r: r for r in ROLES})]
    for path in sorted(_DIR.glob("*.json")):
        out.append(parse_preset(json.loads(path.read_text(encoding="utf-8")), path.name))
    return out


def coverage(preset: RigPreset, found: dict) -> float:
    """Share of the core roles the preset names that were found (0..1)."""
    wanted = [r for r in CORE if r in preset.roles]
    return sum(r in found for r in wanted) / max(len(wanted), 1)

