"""STL mesh reader (pure numpy), binary or ascii; corners at one position are welded into a vertex."""
import re
import struct

import numpy as np

from ..errors import ArticulaInputError
from .polymesh import PolyMesh, check_finite, finish_mesh, parse_numbers, read_bytes

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_STL_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


def read_stl(path: str) -> PolyMesh:
    """STL, binary or ascii.  Triangles come as separate corners; corners at exactly the same
    position are welded into one vertex, numbered in order of first appearance (so two files with the
    same triangles in the same order get the same vertex numbering)."""
    data = read_bytes(path)
    if len(data) >= 84:
        (n,) = struct.unpack_from("<I", data, 80)
        if len(data) == 84 + 50 * n:
            corners = np.frombuffer(data, _STL_RECORD, n, 84)["v"].reshape(-1, 3)
            return _weld(path, corners)
    if data.lstrip()[:5].lower() != b"solid":
        raise ArticulaInputError(f"{path}: not an STL file (neither ascii 'solid' nor a binary file of "
                                 f"the size its triangle count implies)")
    found = _STL_VERTEX.findall(data)
    facets = len(re.findall(rb"\bendloop\b", data))
    if len(found) != 3 * facets:
        raise ArticulaInputError(f"{path}: ascii STL has {len(found)} vertex lines for {facets} facets "
                                 f"(3 per facet expected)")
    corners = parse_numbers(found, np.float64, path, "vertex coordinate").reshape(-1, 3)
    return _weld(path, corners)


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
