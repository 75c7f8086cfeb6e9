"""The model bundle: one ``.npz`` file (format "articula-model/1") holding a model and, optionally,
poses and provenance (docs/skinning.md).  Keys: ``format``; the model's :data:`MODEL_KEYS`
(``rest_vertices`` (V, 3) float64, ``faces`` (F, 3) int32, ``bone_names`` (B,) str, ``parents`` (B,)
int32, ``heads``/``tails`` (B, 3) and ``frames`` (B, 3, 3) float64, ``anchor`` (V,) int32,
``twist_weights``/``swing_weights`` (V, B) float32, as in :class:`~..rig.model.Model`); the poses'
:data:`POSE_KEYS` (``pose_rotations`` (N, B, 4), ``pose_translations`` (N, 3), ``pose_scales`` (N,));
``provenance``, a JSON string; optionally further numeric arrays (``extra``, e.g. a tracked bundle's
pass-1 state, :mod:`solver.track.trail`).  Files are read with ``allow_pickle=False``; a broken file raises
:class:`ArticulaInputError` naming the key and the problem, a missing file names the path.  Pose
quaternions whose norm is within ``QUAT_RENORM_TOL`` (1e-4) of 1 are normalised on load, with a note in
``Bundle.notes`` that the operators and batch commands show.
"""
import json
import os
import zipfile
from dataclasses import dataclass, field

import numpy as np

from ..errors import ArticulaInputError
from ..rig.model import Model, Poses, Skeleton
from .atomic import written_through

FORMAT = "articula-model/1"
MODEL_KEYS = ("rest_vertices", "faces", "bone_names", "parents", "heads", "tails", "frames",
              "anchor", "twist_weights", "swing_weights")
POSE_KEYS = ("pose_rotations", "pose_translations", "pose_scales")


@dataclass
class Bundle:
    model: Model
    poses: Poses = None
    provenance: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)      # what loading changed (e.g. normalised quaternions)
    extra: dict = field(default_factory=dict)      # further numeric arrays by key


def temporary_path(path) -> str:
    """The name :func:`save_bundle` writes to before renaming to ``path`` (a stopped writer may leave it)."""
    return os.fspath(path) + ".tmp.npz"


def save_bundle(path, model: Model, poses: Poses = None, provenance: dict = None, extra: dict = None) -> None:
    """Validate and write ``model`` (and ``poses``, ``provenance``: a JSON-serialisable dict, ``extra``:
    further numeric or boolean arrays by key) to ``path``.  The file is written to :func:`temporary_path`
    first and renamed, so a failure never leaves a half-written bundle (nor the temporary file); a path
    that cannot be written raises :class:`ArticulaInputError`."""
    model.validate()
    sk = model.skeleton
    arrays = {
        "format": np.array(FORMAT),
        "rest_vertices": model.rest_vertices.astype(np.float64),
        "faces": model.faces.astype(np.int32),
        "bone_names": np.array(sk.names, dtype=np.str_),
        "parents": sk.parents.astype(np.int32),
        "heads": sk.heads, "tails": sk.tails, "frames": sk.frames,
        "anchor": model.anchor.astype(np.int32),
        "twist_weights": model.twist_weights.astype(np.float32),
        "swing_weights": model.swing_weights.astype(np.float32),
    }
    if poses is not None:
        poses.validate(sk.num_bones)
        arrays.update(pose_rotations=poses.rotations, pose_translations=poses.translations,
                      pose_scales=poses.scales)
    try:
        text = json.dumps(provenance or {})
    except (TypeError, ValueError) as exc:
        raise ArticulaInputError(f"provenance: not JSON-serialisable ({exc})") from exc
    arrays["provenance"] = np.array(text)
    for key, value in (extra or {}).items():
        value = np.asarray(value)
        if key in arrays or key in POSE_KEYS or value.dtype.kind not in "fiub":
            raise ArticulaInputError(f"extra array {key!r}: a bundle key of its own, or not numeric ({value.dtype})")
        arrays[key] = value
    path, tmp = os.fspath(path), temporary_path(path)
    with written_through(path, tmp, "the bundle"), open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def _read_arrays(path) -> dict:
    """Every array of the ``.npz`` at ``path`` by key; refuses anything else (not a zip, pickled objects,
    members that are not ``.npy`` arrays) with a message naming the file and the key."""
    path = os.fspath(path)
    if not path.strip():
        raise ArticulaInputError("no bundle file given")
    if not os.path.isfile(path):
        raise ArticulaInputError(f"{path}: no such bundle file")
    not_npz = f"{path}: not a model bundle (not a valid .npz archive of arrays)"
    if not zipfile.is_zipfile(path):
        raise ArticulaInputError(not_npz)
    arrays = {}
    try:
        with np.load(path, allow_pickle=False) as data:
            for key in data.files:
                try:
                    arrays[key] = data[key]
                except ValueError as exc:
                    if "pickle" in str(exc):
                        raise ArticulaInputError(f"{path}: key {key!r} holds Python objects (pickled), which a "
                                                 f"model bundle never contains") from None
                    raise
    except ArticulaInputError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ArticulaInputError(f"{not_npz}: {exc}") from exc
    if not all(isinstance(a, np.ndarray) for a in arrays.values()):
        raise ArticulaInputError(not_npz)
    return arrays


def _get(arrays, key, kind, path):
    if key not in arrays:
        raise ArticulaInputError(f"{path}: missing key {key!r}")
    a = arrays[key]
    if kind == "float" and a.dtype.kind not in "fiu":
        raise ArticulaInputError(f"{path}: key {key!r} must be numeric, got dtype {a.dtype}")
    if kind == "int" and a.dtype.kind not in "iu":
        raise ArticulaInputError(f"{path}: key {key!r} must be integer, got dtype {a.dtype}")
    if kind == "str" and a.dtype.kind != "U":
        raise ArticulaInputError(f"{path}: key {key!r} must be a string array, got dtype {a.dtype}")
    return a


def load_bundle(path) -> Bundle:
    """Read and validate a bundle; returns ``Bundle(model, poses or None, provenance dict)``."""
    arrays = _read_arrays(path)
    fmt = _get(arrays, "format", "str", path)
    if fmt.shape != ():
        raise ArticulaInputError(f"{path}: key 'format' must be one string, got shape {fmt.shape}")
    if str(fmt) != FORMAT:
        raise ArticulaInputError(f"{path}: key 'format' is {str(fmt)!r}, expected {FORMAT!r}")
    g = {k: _get(arrays, k, "int" if k in ("faces", "parents", "anchor") else
                 "str" if k == "bone_names" else "float", path) for k in MODEL_KEYS}
    if g["bone_names"].ndim != 1:
        raise ArticulaInputError(f"{path}: key 'bone_names' must be 1-D, got shape {g['bone_names'].shape}")
    skeleton = Skeleton(list(g["bone_names"]), g["parents"], g["heads"], g["tails"], g["frames"])
    model = Model(g["rest_vertices"], g["faces"], skeleton, g["anchor"], g["twist_weights"], g["swing_weights"])
    try:
        model.validate()
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{path}: {exc}") from exc
    poses, notes = _load_poses(arrays, path, skeleton.num_bones)
    provenance = {}
    if "provenance" in arrays:
        try:
            provenance = json.loads(str(_get(arrays, "provenance", "str", path)))
        except ValueError as exc:
            raise ArticulaInputError(f"{path}: key 'provenance' is not valid JSON ({exc})") from exc
        if not isinstance(provenance, dict):
            raise ArticulaInputError(f"{path}: key 'provenance' must hold a JSON object")
    known = {"format", "provenance", *MODEL_KEYS, *POSE_KEYS}
    extra = {k: a for k, a in arrays.items() if k not in known and a.dtype.kind in "fiub"}
    return Bundle(model, poses, provenance, notes, extra)


def _load_poses(arrays, path, num_bones):
    present = [k for k in POSE_KEYS if k in arrays]
    if not present:
        return None, []
    if "pose_rotations" not in arrays:
        raise ArticulaInputError(f"{path}: key {present[0]!r} present but 'pose_rotations' missing")
    rot = _get(arrays, "pose_rotations", "float", path)
    n = len(rot) if rot.ndim else 0
    trans = _get(arrays, "pose_translations", "float", path) if "pose_translations" in arrays else np.zeros((n, 3))
    scales = _get(arrays, "pose_scales", "float", path) if "pose_scales" in arrays else np.ones(n)
    poses = Poses(rot, trans, scales)
    note = poses.normalise_near_unit()
    try:
        poses.validate(num_bones)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{path}: {exc}") from exc
    return poses, [f"{path}: {note}"] if note else []
