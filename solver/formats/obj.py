"""Wavefront OBJ mesh reader (pure numpy): ``v`` and ``f`` lines parsed at C speed where possible.
The file's first kilobytes must look like OBJ (:func:`check_obj`) before it is read whole."""
import re

import numpy as np

from ..errors import ArticulaInputError
from .bounded import HEAD_BYTES, all_numbers, check_size, complete_lines, read_bytes, read_head
from .polymesh import PolyMesh, fast_numbers, finish_mesh

#: Statements of the OBJ specification (and ``#`` comments); a file whose first lines start with
#: anything else is not an OBJ file.
OBJ_KEYWORDS = frozenset(
    b"v vt vn vp f l p o g s mg usemtl mtllib usemap maplib cstype deg bmat step curv curv2 surf parm trim "
    b"hole scrv sp end con bevel c_interp d_interp lod shadow_obj trace_obj ctech stech call csh".split())

_SLASH_PART = re.compile(rb"/\S*")
_V_ROWS = re.compile(rb"^v[ \t]([^\n]*)", re.M)
_F_ROWS = re.compile(rb"^f[ \t]([^\n]*)", re.M)
_V_ROWS_INDENTED = re.compile(rb"^[ \t]*v[ \t]+([^\n]*)", re.M)   # slower; only when lines are indented
_F_ROWS_INDENTED = re.compile(rb"^[ \t]*f[ \t]+([^\n]*)", re.M)


def read_obj(path: str) -> PolyMesh:
    """Wavefront OBJ: ``v`` and ``f`` lines (polygons; ``v/vt/vn`` corners use the vertex index;
    negative indices count back from the last vertex defined before the face).  Groups, objects,
    materials, texture coordinates, normals and lines are ignored; all groups form one mesh."""
    check_obj(path)
    data = read_bytes(path)
    data = data[3:] if data.startswith(b"\xef\xbb\xbf") else data   # UTF-8 byte-order mark
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
            raise ArticulaInputError(f"{path}, line {_line_of(data, v_re, short[0])}: vertex {short[0] + 1} "
                                     "has fewer than 3 coordinates")
        try:
            vertices = np.array(rows, dtype=bytes).astype(np.float64)
        except ValueError:
            bad = next((i for i, r in enumerate(rows) if not all_numbers(r)), 0)
            raise ArticulaInputError(f"{path}, line {_line_of(data, v_re, bad)}: bad vertex coordinate in "
                                     f"{b' '.join(rows[bad]).decode(errors='replace')!r}") from None
    vertices = vertices.reshape(-1, 3)
    f_rows = f_re.findall(data)
    if not f_rows:
        return finish_mesh(path, vertices, np.zeros(0, np.int64), np.zeros(0, np.int64))
    # Faces joined with " 0 " (0 is never a valid OBJ index) so row ends survive number parsing.
    text = _SLASH_PART.sub(b"", b" 0 ".join(f_rows)) + b" 0"
    idx = fast_numbers(text, np.int64, None)
    ends = np.flatnonzero(idx == 0) if idx is not None else None
    if ends is None or len(ends) != len(f_rows) or idx[-1] != 0:   # bad token (parsing stopped) or index 0
        _bad_faces(path, data, f_re, f_rows)
    sizes = np.diff(np.append(-1, ends)) - 1
    idx = idx[idx != 0]
    if (idx < 0).any():
        base = np.repeat(_vertices_before_faces(data), sizes)
        idx = np.where(idx < 0, base + idx, idx - 1)
    else:
        idx -= 1
    return finish_mesh(path, vertices, sizes, idx, index_base=1)


def check_obj(path: str) -> None:
    """Refuse a file whose first kilobytes do not look like OBJ (binary data, or a line that starts with
    no OBJ statement) or that is larger than the scan limit, reading only its first bytes."""
    head, size = read_head(path)
    if b"\0" in head:
        raise ArticulaInputError(f"{path}: not an OBJ text file (binary data)")
    head = head[3:] if head.startswith(b"\xef\xbb\xbf") else head   # UTF-8 byte-order mark
    continued = False
    for n, line in enumerate(complete_lines(head, size is not None and size <= HEAD_BYTES), 1):
        words = line.split()
        if words and not continued and not words[0].startswith(b"#") and words[0] not in OBJ_KEYWORDS:
            raise ArticulaInputError(f"{path}, line {n}: not an OBJ file (the line starts with "
                                     f"{words[0][:20].decode(errors='replace')!r}, not an OBJ statement "
                                     "such as v, vt, vn, f, o, g)")
        continued = line.rstrip().endswith(b"\\")
    check_size(path, size)



def _line_of(data: bytes, regex, k: int) -> int:
    """Line number (from 1) of the ``k``-th (from 0) match of ``regex`` in ``data``."""
    for i, m in enumerate(regex.finditer(data)):
        if i == k:
            return data.count(b"\n", 0, m.start()) + 1
    return 0


def _bad_faces(path, data, f_re, f_rows):
    """Raise naming the line of the first face with a bad index token or index 0."""
    for k, row in enumerate(f_rows):
        tokens = _SLASH_PART.sub(b"", row).split()
        bad = next((t for t in tokens if not t.lstrip(b"-").isdigit()), None)
        if bad is not None:
            raise ArticulaInputError(f"{path}, line {_line_of(data, f_re, k)}: bad face index "
                                     f"{bad.decode(errors='replace')!r}")
        if b"0" in tokens:
            raise ArticulaInputError(f"{path}, line {_line_of(data, f_re, k)}: face {k + 1} uses vertex index 0 "
                                     "(OBJ indices start at 1)")
    raise ArticulaInputError(f"{path}: bad face lines")


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
