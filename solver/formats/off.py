"""Object File Format (OFF) mesh reader (pure numpy).  The header and counts are checked from the
file's first bytes (:func:`check_off`) before it is read whole."""
import re

import numpy as np

from ..errors import ArticulaInputError
from .bounded import check_size, read_bytes, read_head, size_text
from .polymesh import PolyMesh, fast_numbers, finish_mesh, parse_numbers


def read_off(path: str) -> PolyMesh:
    """Object File Format: ``OFF`` (or ``COFF``/``NOFF``/``CNOFF``) header, counts, vertex lines
    (first three numbers used), face lines ``n i1 .. in [colour]``.  ``#`` starts a comment."""
    check_off(path)
    data = read_bytes(path)
    nv, nf, lines, rest = _header(path, data)
    vlines, flines = lines[rest:rest + nv], lines[rest + nv:rest + nv + nf]
    if len(vlines) < nv or len(flines) < nf:
        raise ArticulaInputError(f"{path}: OFF file declares {nv} vertices and {nf} faces but ends early")
    vertices = fast_numbers(b" ".join(vlines), np.float64, 3 * nv)
    if vertices is None:   # colours after the coordinates, or bad numbers: line by line
        rows = [ln.split()[:3] for ln in vlines]
        if any(len(r) < 3 for r in rows):
            i = next(i for i, r in enumerate(rows) if len(r) < 3)
            raise ArticulaInputError(f"{path}: vertex {i + 1} has fewer than 3 coordinates")
        vertices = parse_numbers(rows, np.float64, path, "vertex coordinate")
    if not nf:
        return finish_mesh(path, vertices, np.zeros(0, np.int64), np.zeros(0, np.int64))
    k = int(flines[0].split()[0]) if flines[0].split()[0].isdigit() else -1
    flat = fast_numbers(b" ".join(flines), np.int64, nf * (k + 1)) if k > 0 else None
    if flat is not None and (flat[::k + 1] == k).all():   # every face has k corners and nothing else
        table = flat.reshape(nf, k + 1)
        return finish_mesh(path, vertices, table[:, 0], table[:, 1:].reshape(-1))
    rows = [ln.split() for ln in flines]
    sizes = parse_numbers([r[0] for r in rows], np.int64, path, "face size")
    for i, (n, r) in enumerate(zip(sizes.tolist(), rows)):
        if len(r) < n + 1:
            raise ArticulaInputError(f"{path}: face {i + 1} declares {n} corners but lists {len(r) - 1}")
    corners = parse_numbers([t for n, r in zip(sizes.tolist(), rows) for t in r[1:n + 1]], np.int64, path,
                       "face index")
    return finish_mesh(path, vertices, sizes, corners)


def _header(path: str, data: bytes):
    """``(vertex count, face count, non-empty lines without comments, index of the first vertex line)``
    of OFF text (the whole file or its first bytes)."""
    if b"#" in data:
        data = re.sub(rb"#[^\n]*", b"", data)
    lines = [ln for ln in data.splitlines() if ln.strip()]
    head = lines[0].split() if lines else []
    if not head or not head[0].endswith(b"OFF") or head[0].startswith(b"4"):
        raise ArticulaInputError(f"{path}: not an OFF file (first word must be OFF)")
    counts, rest = head[1:], 1
    if len(counts) < 3 and len(lines) > 1:
        counts, rest = counts + lines[1].split(), 2
    try:
        nv, nf = int(counts[0]), int(counts[1])
        if nv < 0 or nf < 0:
            raise ValueError
    except (IndexError, ValueError):
        raise ArticulaInputError(f"{path}: OFF header has no vertex and face counts") from None
    return nv, nf, lines, rest


def check_off(path: str) -> None:
    """Refuse a file whose first bytes are not an OFF header with counts, whose counts need more bytes than
    the file has (each vertex line at least 6, each face line at least 2), or over the scan limit."""
    head, size = read_head(path)
    nv, nf, _, _ = _header(path, head)
    if size is not None and 6 * nv + 2 * nf > size:
        raise ArticulaInputError(f"{path}: the OFF header declares {nv} vertices and {nf} faces, which need at "
                                 f"least {size_text(6 * nv + 2 * nf)}, but the file has {size_text(size)}; "
                                 "truncated?")
    check_size(path, size)
