"""The built-in template body: the MakeHuman base mesh with a compact humanoid rig and a linear macro
shape basis, used when no model is given (depth-camera tracking dissertation, ch. 5/6: the template whose
limb lengths and surface adapt to the person).

The file ``data/template_body.npz`` (format "articula-template/1", built by ``tools/make_template_body.py``)
holds the base model under the model-bundle keys (docs/skinning.md: ``rest_vertices`` (V, 3) metres, Z up,
facing -Y, feet at z = 0; ``faces``; ``bone_names`` with ``.L``/``.R`` suffixes, parents before children;
``heads``, ``tails``, ``frames``; ``anchor``; ``twist_weights``, ``swing_weights``), and the shape basis:
``basis_names`` (K,); ``basis_macros`` (K,) the MakeHuman macro each vector moves, from the macro value
``basis_starts`` (K,) to ``basis_ends`` (K,) (one vector per linear piece of the macro's path away from
its default); ``vertex_deltas`` (K, V, 3), ``head_deltas`` and ``tail_deltas`` (K, B, 3) in metres (stored
as float16/float32, float64 once loaded), both with the body re-grounded (feet at z = 0) and the joints
placed on each shaped mesh; ``macro_names`` and ``macro_defaults`` (the macros of the base body), ``rig``
and ``provenance`` (JSON).  The basis reproduces MakeHuman to within a millimetre when one macro moves;
with several, the interactions of MakeHuman's combined targets are left out (a least-squares fit absorbs part of them).
"""
from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass, field

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import rotation_between
from ..rig.model import Model, Skeleton

FORMAT = "articula-template/1"
TEMPLATE_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "template_body.npz")
_KINDS = {"rest_vertices": "f", "faces": "i", "bone_names": "U", "parents": "i", "heads": "f", "tails": "f",
          "frames": "f", "anchor": "i", "twist_weights": "f", "swing_weights": "f", "basis_names": "U",
          "basis_macros": "U", "basis_starts": "f", "basis_ends": "f", "vertex_deltas": "f", "head_deltas": "f",
          "tail_deltas": "f", "macro_names": "U", "macro_defaults": "f", "rig": "U", "provenance": "U",
          "format": "U"}
_SCALARS = ("rig", "provenance", "format")      # one string each


@dataclass
class TemplateBody:
    """The base model and its linear shape basis.

    basis_names, basis_macros (K,) str; basis_starts, basis_ends (K,) macro values at coefficient 0 and 1;
    vertex_deltas (K, V, 3), head_deltas and tail_deltas (K, B, 3) float64 metres; macro_defaults
    ``{macro: value}`` of the base body; provenance: dict.
    """
    base: Model
    basis_names: list
    basis_macros: list
    basis_starts: np.ndarray
    basis_ends: np.ndarray
    vertex_deltas: np.ndarray
    head_deltas: np.ndarray
    tail_deltas: np.ndarray
    macro_defaults: dict
    rig: str = ""
    provenance: dict = field(default_factory=dict)

    @property
    def num_basis(self) -> int:
        return len(self.basis_names)

    def _coefficients(self, coefficients) -> np.ndarray:
        c = np.asarray(coefficients, dtype=np.float64)
        if c.shape != (self.num_basis,) or not np.isfinite(c).all():
            raise ArticulaInputError(f"shape coefficients: expected {self.num_basis} finite values, got shape "
                                     f"{c.shape}")
        return c

    def shaped(self, coefficients) -> Model:
        """The model with rest vertices ``base + sum_k c_k vertex_deltas[k]`` and heads/tails moved alike.

        Each frame is the base frame turned by the smallest rotation taking its old Y axis onto the new
        head -> tail direction (the bone's roll is kept); faces, anchors and weights are the base's."""
        c = self._coefficients(coefficients)
        sk = self.base.skeleton
        heads = sk.heads + np.einsum("k,kbi->bi", c, self.head_deltas)
        tails = sk.tails + np.einsum("k,kbi->bi", c, self.tail_deltas)
        length = np.linalg.norm(tails - heads, axis=1)
        if (length < 1e-9).any():
            b = int(np.argmin(length))
            raise ArticulaInputError(f"shape coefficients: bone {b} ({sk.names[b]!r}) collapses to zero length")
        turn = rotation_between(_unit(sk.tails - sk.heads), _unit(tails - heads))
        skeleton = Skeleton(list(sk.names), sk.parents.copy(), heads, tails, turn @ sk.frames)
        vertices = self.base.rest_vertices + np.einsum("k,kvi->vi", c, self.vertex_deltas)
        return Model(vertices, self.base.faces.copy(), skeleton, self.base.anchor.copy(),
                     self.base.twist_weights.copy(), self.base.swing_weights.copy())

    def macro_coefficients(self, macros: dict) -> np.ndarray:
        """(K,) coefficients for MakeHuman macro values in [0, 1] (others at their default): a vector from
        start s to end e gets ``clip((value - s) / (e - s), 0, 1)``, e.g. weight 0.8 -> 0.6 on "weight-high".
        Unknown macro names and values outside [0, 1] raise :class:`ArticulaInputError`."""
        known = sorted(set(self.basis_macros))
        c = np.zeros(self.num_basis)
        for name, value in (macros or {}).items():
            if name not in known:
                raise ArticulaInputError(f"macros: unknown macro {name!r} (known: {', '.join(known)})")
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ArticulaInputError(f"macros: {name!r} = {value!r} is not a number") from None
            if not 0.0 <= v <= 1.0:
                raise ArticulaInputError(f"macros: {name!r} = {v} is outside [0, 1]")
            for k, macro in enumerate(self.basis_macros):
                if macro == name:
                    s, e = self.basis_starts[k], self.basis_ends[k]
                    c[k] = np.clip((v - s) / (e - s), 0.0, 1.0)
        return c


def _unit(d: np.ndarray) -> np.ndarray:
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _read(path) -> dict:
    """Every array of the ``.npz`` at ``path``; ArticulaInputError naming the file for anything else."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ArticulaInputError(f"{path}: no such template file")
    if not zipfile.is_zipfile(path):
        raise ArticulaInputError(f"{path}: not a template body (not an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ArticulaInputError(f"{path}: not a readable template body ({exc})") from None


def _arrays(path) -> dict:
    arrays = _read(path)
    fmt = arrays.get("format")
    if fmt is None or fmt.dtype.kind != "U" or str(fmt) != FORMAT:
        raise ArticulaInputError(f"{path}: key 'format' is {None if fmt is None else str(fmt)!r}, "
                                 f"expected {FORMAT!r}")
    for key, kind in _KINDS.items():
        if key not in arrays:
            raise ArticulaInputError(f"{path}: missing key {key!r}")
        dtype_kind = arrays[key].dtype.kind
        if dtype_kind != kind and not (kind == "f" and dtype_kind in "iu") and not (kind == "i" and dtype_kind == "u"):
            raise ArticulaInputError(f"{path}: key {key!r} has dtype {arrays[key].dtype}")
        if kind == "U" and arrays[key].ndim != (0 if key in _SCALARS else 1):
            raise ArticulaInputError(f"{path}: key {key!r} has shape {arrays[key].shape}")
    return arrays


def _check_basis(t: TemplateBody, path) -> None:
    """Shapes of the basis arrays against the base model (ArticulaInputError naming the file and key)."""
    K, V, B = t.num_basis, t.base.num_vertices, t.base.skeleton.num_bones
    shapes = {"basis_macros": (len(t.basis_macros),), "basis_starts": t.basis_starts.shape,
              "basis_ends": t.basis_ends.shape, "vertex_deltas": t.vertex_deltas.shape,
              "head_deltas": t.head_deltas.shape, "tail_deltas": t.tail_deltas.shape}
    want = {"vertex_deltas": (K, V, 3), "head_deltas": (K, B, 3), "tail_deltas": (K, B, 3)}
    for key, got in shapes.items():
        if got != want.get(key, (K,)):
            raise ArticulaInputError(f"{path}: key {key!r}: expected shape {want.get(key, (K,))}, got {got}")
    for key in ("basis_starts", "basis_ends", "vertex_deltas", "head_deltas", "tail_deltas"):
        if not np.isfinite(getattr(t, key)).all():
            raise ArticulaInputError(f"{path}: key {key!r} holds non-finite values")
    if (t.basis_starts == t.basis_ends).any():
        raise ArticulaInputError(f"{path}: key 'basis_ends': a basis vector starts and ends at the same value")


def load_template(path=TEMPLATE_PATH) -> TemplateBody:
    """Read and check a template body file (:class:`TemplateBody`; deltas as float64)."""
    a = _arrays(path)
    skeleton = Skeleton(list(a["bone_names"]), a["parents"], a["heads"], a["tails"], a["frames"])
    base = Model(a["rest_vertices"], a["faces"], skeleton, a["anchor"], a["twist_weights"], a["swing_weights"])
    try:
        base.validate()
        provenance = json.loads(str(a["provenance"]))
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{path}: {exc}") from None
    except ValueError as exc:
        raise ArticulaInputError(f"{path}: key 'provenance' is not valid JSON ({exc})") from None
    if not isinstance(provenance, dict):
        raise ArticulaInputError(f"{path}: key 'provenance' must hold a JSON object")
    if a["macro_names"].shape != a["macro_defaults"].shape or a["macro_names"].ndim != 1:
        raise ArticulaInputError(f"{path}: key 'macro_defaults': shape {a['macro_defaults'].shape} does not "
                                 f"match 'macro_names' {a['macro_names'].shape}")
    defaults = dict(zip([str(n) for n in a["macro_names"]], [float(v) for v in a["macro_defaults"]]))
    template = TemplateBody(base, [str(n) for n in a["basis_names"]], [str(m) for m in a["basis_macros"]],
                            a["basis_starts"].astype(np.float64), a["basis_ends"].astype(np.float64),
                            a["vertex_deltas"].astype(np.float64), a["head_deltas"].astype(np.float64),
                            a["tail_deltas"].astype(np.float64), defaults, str(a["rig"]), provenance)
    _check_basis(template, path)
    return template
