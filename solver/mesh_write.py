"""Fast triangle-mesh writers (binary PLY, OBJ) for generated scan sequences.

The counterpart of ``solver.meshfiles`` (the readers).  Both writers take ``vertices`` (V, 3) in
metres and ``faces`` (F, 3) vertex ids (0-based), are vectorised (no per-vertex Python loop) and write
atomically (temporary file, then rename), so a failed run never leaves half a file.
"""
from __future__ import annotations

import os

import numpy as np

from .errors import ArticulaInputError


def _check(path, vertices, faces):
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ArticulaInputError(f"{path}: vertices must be (V, 3), got {v.shape}")
    if f.size and (f.ndim != 2 or f.shape[1] != 3):
        raise ArticulaInputError(f"{path}: faces must be (F, 3) triangles, got {f.shape}")
    f = f.reshape(-1, 3).astype(np.int64)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ArticulaInputError(f"{path}: face indices out of range 0..{len(v) - 1}")
    if not np.isfinite(v).all():
        raise ArticulaInputError(f"{path}: vertices contain NaN or infinite coordinates")
    return v, f


def _atomic_write(path, chunks):
    tmp = f"{path}.part{os.getpid()}"
    try:
        with open(tmp, "wb") as fh:
            for chunk in chunks:
                fh.write(chunk)
        os.replace(tmp, path)
    except OSError as exc:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise ArticulaInputError(f"{path}: cannot write ({exc.strerror or exc})") from exc


def write_ply(path, vertices, faces, comment: str = "") -> None:
    """Binary little-endian PLY: float32 x/y/z, faces as ``uchar`` count + ``int`` indices."""
    path = os.fspath(path)
    v, f = _check(path, vertices, faces)
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {line}" for line in comment.splitlines() if line]
    header += [f"element vertex {len(v)}", "property float x", "property float y", "property float z",
               f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    face_rec = np.zeros(len(f), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
    face_rec["n"] = 3
    face_rec["idx"] = f
    _atomic_write(path, ["\n".join(header).encode("ascii") + b"\n",
                         v.astype("<f4").tobytes(), face_rec.tobytes()])


def write_obj(path, vertices, faces, comment: str = "") -> None:
    """Wavefront OBJ with ``v x y z`` (6 decimals, i.e. micrometres) and 1-based ``f a b c`` lines."""
    path = os.fspath(path)
    v, f = _check(path, vertices, faces)
    head = "".join(f"# {line}\n" for line in comment.splitlines() if line)
    vtext = _format_rows("v", v, "%.6f")
    ftext = _format_rows("f", f + 1, "%d")
    _atomic_write(path, [head.encode(), vtext.encode(), ftext.encode()])


def _format_rows(tag, rows, fmt):
    """Vectorised formatting of an (N, 3) array as ``tag a b c`` lines."""
    if len(rows) == 0:
        return ""
    line = f"{tag} {fmt} {fmt} {fmt}\n"
    return (line * len(rows)) % tuple(rows.ravel().tolist())
