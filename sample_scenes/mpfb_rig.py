"""MPFB2 rigs (``rigs/standard/rig.<name>.json`` + ``weights.<name>.json``) placed on a (shaped) mesh.

Rig file: ``{bone: {"head": spec, "tail": spec, "parent": name or "", "roll": radians, ...}}`` (the
mixamo file wraps it in ``{"bones": ...}``).  A joint spec places a point by ``strategy``:
``CUBE`` (centre of the ``cube_name`` joint cube), ``VERTEX`` (``vertex_index``), ``MEAN``
(mean of ``vertex_indices``); otherwise ``default_position`` (world metres, for the default human).
Indices refer to the full 19,158-vertex base mesh, so joints are placed on the shaped full mesh.

Frames follow Blender's edit-bone convention (``roll`` is Blender's bone roll): Y = (tail - head)/|.|;
X, Z = the world X, Z axes carried by the shortest-arc rotation from world +Y to Y, then rotated by
``roll`` about Y (right-handed).  A bone pointing along -Y takes the 180-degree turn about Z instead.

Names: left/right markers become Blender's ``.L``/``.R`` suffix: ``LeftArm`` -> ``Arm.L``,
``LHipJoint`` -> ``HipJoint.L``, ``upperarm_l`` -> ``upperarm.L``, ``mixamorig:RightHand`` ->
``Hand.R`` (namespace prefixes are dropped); names already ending in ``.L``/``.R`` are kept.
Bone order: depth-first from the root, siblings in file order, so parents precede children and
bone 0 is the root.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..solver.errors import ArticulaInputError
from .assets import ensure_assets
from .makehuman import BODY_VERTEX_COUNT, BaseMesh

RIGS = ("cmu_mb", "game_engine", "default", "mixamo")


@dataclass(frozen=True)
class RigSpec:
    """A parsed rig file in topological order.

    source_names: original MPFB bone names; names: ``.L``/``.R`` names; parents (B,) int32 (-1 root);
    head_specs, tail_specs: joint specs (dicts); rolls (B,) radians.
    """
    rig: str
    source_names: tuple
    names: tuple
    parents: np.ndarray
    head_specs: tuple
    tail_specs: tuple
    rolls: np.ndarray


def side_name(name: str) -> str:
    """Map a rig bone name to the ``.L``/``.R`` convention (see the module docstring)."""
    base = name.split(":")[-1]
    if re.search(r"\.[LR]$", base):
        return base
    patterns = ((r"^(.+)_([lLrR])$", 1, 2), (r"^(Left|Right)(.+)$", 2, 1), (r"^([LR])([A-Z].*)$", 2, 1))
    for pattern, keep, side in patterns:
        m = re.match(pattern, base)
        if m:
            return f"{m.group(keep)}.{m.group(side)[0].upper()}"
    return base


def _depth_first(bones: dict) -> list:
    roots = [b for b, d in bones.items() if not d.get("parent")]
    if len(roots) != 1:
        raise ArticulaInputError(f"rig: expected one root bone, found {roots}")
    kids: dict = {}
    for b, d in bones.items():
        if d.get("parent"):
            if d["parent"] not in bones:
                raise ArticulaInputError(f"rig: bone {b!r} has unknown parent {d['parent']!r}")
            kids.setdefault(d["parent"], []).append(b)
    order, stack = [], [roots[0]]
    while stack:
        b = stack.pop()
        order.append(b)
        stack.extend(reversed(kids.get(b, [])))
    if len(order) != len(bones):
        raise ArticulaInputError("rig: some bones are not connected to the root")
    return order


@lru_cache(maxsize=None)
def load_rig(rig: str) -> RigSpec:
    """Parse ``rig.<rig>.json`` into a :class:`RigSpec` (cached)."""
    if rig not in RIGS:
        raise ArticulaInputError(f"rig: unknown rig {rig!r} (choose from {', '.join(RIGS)})")
    data = json.loads((ensure_assets(verbose=False) / "rigs" / "standard" / f"rig.{rig}.json").read_text())
    bones = data.get("bones", data)
    order = _depth_first(bones)
    index = {b: i for i, b in enumerate(order)}
    names = tuple(side_name(b) for b in order)
    if len(set(names)) != len(names):
        raise ArticulaInputError(f"rig {rig}: bone names collide after mapping to .L/.R")
    parents = np.array([index[bones[b]["parent"]] if bones[b].get("parent") else -1 for b in order], np.int32)
    return RigSpec(rig, tuple(order), names, parents, tuple(bones[b]["head"] for b in order),
                   tuple(bones[b]["tail"] for b in order), np.array([bones[b]["roll"] for b in order], float))


def place_point(spec: dict, vertices: np.ndarray, mesh: BaseMesh) -> np.ndarray:
    """World position (3,) of one joint spec on the full-mesh ``vertices`` (19158, 3)."""
    strategy = spec.get("strategy")
    if strategy == "CUBE" and spec.get("cube_name") in mesh.joint_groups:
        return vertices[mesh.joint_groups[spec["cube_name"]]].mean(axis=0)
    if strategy == "VERTEX":
        return vertices[int(spec["vertex_index"])].copy()
    if strategy == "MEAN":
        return vertices[np.asarray(spec["vertex_indices"], dtype=np.int64)].mean(axis=0)
    return np.asarray(spec["default_position"], dtype=np.float64)


def place_joints(spec: RigSpec, vertices: np.ndarray, mesh: BaseMesh) -> tuple[np.ndarray, np.ndarray]:
    """(heads (B, 3), tails (B, 3)) of the rig on the full-mesh ``vertices``."""
    heads = np.array([place_point(s, vertices, mesh) for s in spec.head_specs])
    tails = np.array([place_point(s, vertices, mesh) for s in spec.tail_specs])
    return heads, tails


def _axis_angle_matrices(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(B, 3, 3) right-handed rotations by ``angles`` (B,) about unit ``axes`` (B, 3) (Rodrigues)."""
    K = np.zeros((len(axes), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    K -= np.swapaxes(K, 1, 2)
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * K @ K


def roll_frames(heads: np.ndarray, tails: np.ndarray, rolls: np.ndarray) -> np.ndarray:
    """Blender edit-bone rest frames (B, 3, 3), columns = local X, Y, Z in world (module docstring)."""
    d = np.asarray(tails, float) - np.asarray(heads, float)
    n = d / np.linalg.norm(d, axis=1, keepdims=True)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    theta = 1.0 + y
    flipped = (theta < 1e-6) & (x * x + z * z < 1e-12)
    t = np.where(flipped, 1.0, theta)
    col_x = np.stack([1 - x * x / t, -x, -x * z / t], axis=1)
    col_z = np.stack([-x * z / t, -z, 1 - z * z / t], axis=1)
    col_x[flipped] = [-1.0, 0.0, 0.0]
    col_z[flipped] = [0.0, 0.0, 1.0]
    base = np.stack([col_x, n, col_z], axis=2)
    return _axis_angle_matrices(n, np.asarray(rolls, float)) @ base


def load_weights(rig: str, spec: RigSpec) -> np.ndarray:
    """(13380, B) float64 LBS weights of the body vertices, rows normalised to sum 1, bone order of ``spec``.

    Entries on helper vertices are dropped; each row is divided by its sum (the mixamo file's rows
    sum to 0.2-1.5).  A body vertex without any weight raises :class:`ArticulaInputError`.
    """
    path = ensure_assets(verbose=False) / "rigs" / "standard" / f"weights.{rig}.json"
    data = json.loads(path.read_text())["weights"]
    index = {b: i for i, b in enumerate(spec.source_names)}
    W = np.zeros((BODY_VERTEX_COUNT, len(index)))
    for bone, pairs in data.items():
        if not pairs:
            continue
        if bone not in index:
            raise ArticulaInputError(f"{path}: weights for unknown bone {bone!r}")
        arr = np.asarray(pairs, dtype=np.float64)
        keep = arr[:, 0] < BODY_VERTEX_COUNT
        W[arr[keep, 0].astype(np.int64), index[bone]] += arr[keep, 1]
    total = W.sum(axis=1)
    if (total <= 0).any():
        raise ArticulaInputError(f"{path}: body vertex {int(np.argmin(total))} has no weight")
    return W / total[:, None]
