"""Wavefront OBJ mesh reader (pure numpy): ``v`` and ``f`` lines parsed at C speed where possible."""
import re

import numpy as np

from ..errors import ArticulaInputError
from .polymesh import PolyMesh, fast_numbers, finish_mesh, parse_numbers, read_bytes

_SLASH_PART = re.compile(rb"/\S*")
_V_ROWS = re.compile(rb"^v[ \t]([^\n]*)", re.M)
_F_ROWS = re.compile(rb"^f[ \t]([^\n]*)", re.M)
_V_ROWS_INDENTED = re.compile(rb"^[ \t]*v[ \t]+([^\n]*)", re.M)   # slower; only when lines are indented
_F_ROWS_INDENTED = re.compile(rb"^[ \t]*f[ \t]+([^\n]*)", re.M)


def read_obj(path: str) -> PolyMesh:
    """Wavefront OBJ: ``v`` and ``f`` lines (polygons; ``v/vt/vn`` corners use the vertex index;
    negative indices count back from the last vertex defined before the face).  Groups, objects,
    materials, texture coordinates, normals and lines are ignored; all groups form one mesh."""
    data = read_bytes(path)
    if b"\0" in data[:4096]:
        raise ArticulaInputError(f"{path}: not an OBJ text file (binary data)")
    data = data.replace(b"\\\r\n", b" ").replace(b"\\\n", b" ")
    indented = data[:1] in (b" ", b"\t") or b"\n " in data or b"\n\t" in data
    v_re, f_re = (_V_ROWS_INDENTED, _F_ROWS_INDENTED) if indented else (_V_ROWS, _F_ROWS)
    v_rows = v_re.findall(data)
    if not v_rows:
        raise ArticulaInputError(f"{path}: no vertices ('v' lines) in this OBJ file")
    vertices = fast_numbers(b" ".join(v_rows), np.float64, 3 * len(v_rows))
    if vertices is None:   # w or colours after x y z, or bad numbers: row by row
        rows = [r.split()[:3] for r in v_rows]
        short = [i for i, r in enumerate(rows) if len(r) < 3]
        if short:
            raise ArticulaInputError(f"{path}: vertex {short[0]} has fewer than 3 coordinates")
        vertices = parse_numbers(rows, np.float64, path, "vertex coordinate")
    vertices = vertices.reshape(-1, 3)
    f_rows = f_re.findall(data)
    if not f_rows:
        return finish_mesh(path, vertices, np.zeros(0, np.int64), np.zeros(0, np.int64))
    # Faces joined with " 0 " (0 is never a valid OBJ index) so row ends survive number parsing.
    text = _SLASH_PART.sub(b"", b" 0 ".join(f_rows)) + b" 0"
    idx = fast_numbers(text, np.int64, None)
    ends = np.flatnonzero(idx == 0) if idx is not None else None
    if ends is None or len(ends) != len(f_rows) or idx[-1] != 0:   # bad token (parsing stopped) or index 0
        bad = next((t for t in text.split() if not t.lstrip(b"-").isdigit()), None)
        if bad is not None:
            raise ArticulaInputError(f"{path}: bad face index {bad.decode(errors='replace')!r}")
        k = next(k for k, r in enumerate(f_rows) if b"0" in _SLASH_PART.sub(b"", r).split())
        raise ArticulaInputError(f"{path}: face {k} uses vertex index 0 (OBJ indices start at 1)")
    sizes = np.diff(np.append(-1, ends)) - 1
    idx = idx[idx != 0]
    if (idx < 0).any():
        base = np.repeat(_vertices_before_faces(data), sizes)
        idx = np.where(idx < 0, base + idx, idx - 1)
    else:
        idx -= 1
    return finish_mesh(path, vertices, sizes, idx)


def _vertices_before_faces(data: bytes) -> np.ndarray:
    """(F,) number of ``v`` lines before each ``f`` line (for negative indices)."""
    out, nv = [], 0
    for line in data.splitlines():
        head = line.lstrip()[:2]
        if head in (b"v ", b"v\t"):
            nv += 1
        elif head in (b"f ", b"f\t"):
            out.append(nv)
    return np.array(out, np.int64)
