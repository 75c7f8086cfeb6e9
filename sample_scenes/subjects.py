"""Subjects: a shaped MakeHuman body with an MPFB2 rig, its LBS weights and the hybrid-skin model.

``make_subject(rig, shape, seed)`` -> :class:`Subject`:

* shape: MakeHuman macros (:mod:`.makehuman`): a dict ``{"gender": 0.0, "weight": 0.9}``, a string of
  presets and assignments ``"female,heavy,age=0.7"`` (:func:`parse_shape`) or None.  Macros not given
  are MakeHuman's defaults when ``seed`` is None, otherwise drawn from adult ranges with
  ``numpy.random.default_rng(seed)`` (:data:`RANDOM_RANGES`).
* mesh: the 13,380 body vertices (metres, Z up, facing -Y), moved vertically so the lowest vertex is at
  z = 0 (x, y keep MakeHuman's origin, x = 0 is the symmetry plane); quads (13,378) and triangles.
* skeleton: joints placed on the shaped full mesh (joint cubes, vertices), Blender roll frames,
  ``.L``/``.R`` names, parents before children (:mod:`.mpfb_rig`); ``source_names`` keeps the MPFB names.
* lbs_weights (V, B): the rig's weights on the body, rows normalised.
* :meth:`Subject.hybrid_model`: an Articula ``Model`` whose anchors and swing/twist weights come from
  the LBS weights (:mod:`.hybrid_weights`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.rig.model import Model, Skeleton
from . import makehuman as mh
from .hybrid_weights import anchors_from_lbs, twist_ramp_weights
from .mpfb_rig import load_rig, load_weights, place_joints, roll_frames

SHAPE_PRESETS = {
    "female": {"gender": 0.0}, "male": {"gender": 1.0}, "heavy": {"weight": 0.9}, "thin": {"weight": 0.1},
    "tall": {"height": 0.7}, "short": {"height": 0.3}, "young": {"age": 0.5}, "old": {"age": 0.875},
    "muscular": {"muscle": 0.9}, "weak": {"muscle": 0.1}, "average": {},
}
#: Ranges of macros drawn at random (adults: age 0.5-0.8 is 25-64 years).  MakeHuman's height targets
#: are large (height 0 / 1 give about 1.3 m / 2.4 m for the default body), hence the narrow range.
RANDOM_RANGES = {"gender": (0.0, 1.0), "age": (0.5, 0.8), "muscle": (0.3, 0.8), "weight": (0.2, 0.8),
                 "height": (0.35, 0.65), "proportions": (0.4, 0.8)}


@dataclass
class Subject:
    """A shaped, rigged body.  Arrays in metres, Z up; see the module docstring."""
    rig: str
    macros: dict
    vertices: np.ndarray
    quads: np.ndarray
    triangles: np.ndarray
    skeleton: Skeleton
    source_names: tuple
    lbs_weights: np.ndarray

    def hybrid_model(self, twist_ramp: bool = True, max_influences: int = 4) -> Model:
        """The hybrid-skin ``Model`` (anchors, swing and twist weights from the LBS weights)."""
        anchor, swing, _ = anchors_from_lbs(self.lbs_weights, self.skeleton.parents, max_influences)
        twist = twist_ramp_weights(self.vertices, self.skeleton, anchor, swing) if twist_ramp else swing
        return Model(self.vertices, self.triangles, self.skeleton, anchor, twist, swing)


def parse_shape(text: str) -> dict:
    """``"female,heavy,age=0.7"`` -> macro dict (presets of :data:`SHAPE_PRESETS` and key=value)."""
    shape: dict = {}
    for token in filter(None, (t.strip() for t in (text or "").split(","))):
        if "=" in token:
            key, value = token.split("=", 1)
            try:
                shape[key.strip()] = float(value)
            except ValueError:
                raise ArticulaInputError(f"shape: {token!r}: the value is not a number") from None
        elif token in SHAPE_PRESETS:
            shape.update(SHAPE_PRESETS[token])
        else:
            raise ArticulaInputError(f"shape: unknown preset {token!r} (known: {', '.join(SHAPE_PRESETS)}, "
                                     f"or macro=value)")
    return shape


def resolve_macros(shape=None, seed: int | None = None) -> dict:
    """Full macro values: given ones, then random (seeded) or default for the others."""
    given = parse_shape(shape) if isinstance(shape, str) else dict(shape or {})
    macros = dict(mh.MACRO_DEFAULTS)
    if seed is not None:
        rng = np.random.default_rng(seed)
        for key, (lo, hi) in RANDOM_RANGES.items():
            macros[key] = float(rng.uniform(lo, hi))
        race = rng.dirichlet(np.ones(len(mh.RACES)))
        macros.update({r: float(x) for r, x in zip(mh.RACES, race)})
    macros.update(given)
    return macros


@lru_cache(maxsize=8)
def _rig_weights(rig: str) -> np.ndarray:
    return load_weights(rig, load_rig(rig))


def make_subject(rig: str = "cmu_mb", shape=None, seed: int | None = None) -> Subject:
    """Build a :class:`Subject` (about 0.1-0.3 s; the parsed assets are cached)."""
    spec = load_rig(rig)
    macros = resolve_macros(shape, seed)
    mesh = mh.load_base_mesh()
    full = mh.shaped_vertices(macros)
    full[:, 2] -= full[:mh.BODY_VERTEX_COUNT, 2].min()
    heads, tails = place_joints(spec, full, mesh)
    skeleton = Skeleton(list(spec.names), spec.parents, heads, tails, roll_frames(heads, tails, spec.rolls))
    skeleton.validate()
    body = full[:mh.BODY_VERTEX_COUNT].copy()
    return Subject(rig, macros, body, mesh.body_quads.copy(), mesh.body_triangles, skeleton,
                   spec.source_names, _rig_weights(rig).copy())
