"""STL mesh reader (pure numpy), binary or ascii; corners at one position are welded into a vertex.
Which of the two a file is, and whether it is an STL at all, is decided from its first bytes and its
size (:func:`check_stl`) before it is read whole."""
import re
import struct

import numpy as np

from ..errors import ArticulaInputError
from .bounded import HEAD_BYTES, check_size, complete_lines, read_bytes, read_head, size_text
from .polymesh import PolyMesh, check_finite, finish_mesh, parse_numbers

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_STL_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


def read_stl(path: str) -> PolyMesh:
    """STL, binary or ascii.  Triangles come as separate corners; corners at exactly the same
    position are welded into one vertex, numbered in order of first appearance (so two files with the
    same triangles in the same order get the same vertex numbering)."""
    binary = check_stl(path)
    data = read_bytes(path)
    if binary:
        (n,) = struct.unpack_from("<I", data, 80)
        if len(data) != 84 + 50 * n:
            raise ArticulaInputError(f"{path}: binary STL changed while being read")
        corners = np.frombuffer(data, _STL_RECORD, n, 84)["v"].reshape(-1, 3)
        return _weld(path, corners)
    found = _STL_VERTEX.findall(data)
    facets = len(re.findall(rb"\bendloop\b", data))
    if len(found) != 3 * facets:
        raise ArticulaInputError(f"{path}: ascii STL has {len(found)} vertex lines for {facets} facets "
                                 f"(3 per facet expected)")
    corners = parse_numbers(found, np.float64, path, "vertex coordinate").reshape(-1, 3)
    return _weld(path, corners)


def check_stl(path: str) -> bool:
    """True for a binary STL (the 84-byte header's triangle count matches the file size), False for an
    ascii one ('solid' then 'facet' or 'endsolid'); refuses anything else and files over the scan limit,
    reading only the first bytes."""
    head, size = read_head(path)
    if size is not None and len(head) >= 84:
        (n,) = struct.unpack_from("<I", head, 80)
        if size == 84 + 50 * n:
            check_size(path, size)
            return True
    lines = [ln.strip().lower() for ln in complete_lines(head, size is not None and size <= HEAD_BYTES)]
    lines = [ln for ln in lines if ln]
    ascii_ok = (b"\0" not in head and head.lstrip()[:5].lower() == b"solid"
                and (len(lines) < 2 or lines[1].startswith((b"facet", b"endsolid"))))
    if not ascii_ok:
        binary = ""
        if len(head) >= 84 and size is not None:
            n = struct.unpack_from("<I", head, 80)[0]
            binary = (f"; as a binary STL its header says {n} triangles ({size_text(84 + 50 * n)}) but the file "
                      f"has {size_text(size)}")
        raise ArticulaInputError(f"{path}: not an STL file (neither ascii 'solid' ... 'facet' nor a binary file "
                                 f"of the size its triangle count implies{binary})")
    check_size(path, size)
    return False


def _weld(path, corners):
    corners = np.asarray(corners, np.float64) + 0.0  # + 0.0 turns -0.0 into 0.0 so both weld
    check_finite(corners, path)
    if not len(corners):
        return finish_mesh(path, corners, np.zeros(0, np.int64), np.zeros(0, np.int64))
    order = np.lexsort(corners.T[::-1])                 # equal positions become neighbours
    srt = corners[order]
    new = np.ones(len(srt), bool)
    new[1:] = (srt[1:] != srt[:-1]).any(axis=1)
    group = np.cumsum(new) - 1                          # weld group of each sorted corner
    first = np.minimum.reduceat(order, np.flatnonzero(new))   # first corner index of each group
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))     # groups numbered by first appearance
    inverse = np.empty(len(corners), np.int64)
    inverse[order] = rank[group]
    return finish_mesh(path, corners[np.sort(first)], np.full(len(corners) // 3, 3), inverse)
