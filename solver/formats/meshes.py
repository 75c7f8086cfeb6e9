"""Readers for polygon-mesh files: OBJ, PLY (ascii and binary), STL (ascii and binary) and OFF.

Pure numpy, no bpy.  Every reader returns a :class:`PolyMesh` and raises ``ArticulaInputError`` with a
message naming the file (and line, face or vertex) for anything it cannot use: missing or unreadable
files, garbage, indices out of range, faces with fewer than three corners, NaN/inf coordinates.

Polygons are kept as Blender keeps them: ``face_sizes`` (F,) corners per face and ``corner_verts`` (C,)
the vertex of every corner, faces one after another.  Faces that use one vertex twice (degenerate, e.g.
after welding an STL) are dropped, as Blender's own importers do.
"""
from __future__ import annotations

import os
import re
import struct
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError

MESH_EXTENSIONS = (".obj", ".ply", ".stl", ".off")


@dataclass(frozen=True, eq=False)
class PolyMesh:
    """A polygon mesh: ``vertices`` (V,3) float64, ``face_sizes`` (F,) int32, ``corner_verts`` (C,) int32
    with C = sum(face_sizes)."""
    vertices: np.ndarray
    face_sizes: np.ndarray
    corner_verts: np.ndarray

    @property
    def face_starts(self) -> np.ndarray:
        """(F,) int32 index of each face's first corner in ``corner_verts``."""
        starts = np.zeros(len(self.face_sizes), np.int32)
        np.cumsum(self.face_sizes[:-1], out=starts[1:])
        return starts

    def triangles(self) -> np.ndarray:
        """(T,3) int32 fan triangulation of every face (a triangle stays itself)."""
        sizes = self.face_sizes.astype(np.int64)
        starts = self.face_starts.astype(np.int64)
        ntri = sizes - 2
        first = np.repeat(starts, ntri)
        k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # 0..n-3 within each face
        cv = self.corner_verts
        return np.stack([cv[first], cv[first + k + 1], cv[first + k + 2]], axis=1).astype(np.int32)

    def topology_difference(self, other: "PolyMesh") -> str | None:
        """None when ``other`` has the same vertex count and identical faces, else how it differs."""
        if len(other.vertices) != len(self.vertices):
            return f"vertex count {len(other.vertices)} vs {len(self.vertices)}"
        if len(other.face_sizes) != len(self.face_sizes):
            return f"face count {len(other.face_sizes)} vs {len(self.face_sizes)}"
        bad = np.flatnonzero(other.face_sizes != self.face_sizes)
        if bad.size:
            k = int(bad[0])
            return f"face {k} has {other.face_sizes[k]} corners vs {self.face_sizes[k]}"
        diff = np.flatnonzero(other.corner_verts != self.corner_verts)
        if diff.size:
            face = int(np.searchsorted(self.face_starts, diff[0], side="right") - 1)
            return f"face {face} differs (vertices {_face(other, face)} vs {_face(self, face)})"
        return None


def _face(mesh: PolyMesh, k: int) -> list:
    s = int(mesh.face_starts[k])
    return mesh.corner_verts[s:s + int(mesh.face_sizes[k])].tolist()


def read_mesh(path: str) -> PolyMesh:
    """Read an OBJ, PLY, STL or OFF file (chosen by extension)."""
    ext = os.path.splitext(path)[1].lower()
    reader = {".obj": read_obj, ".ply": read_ply, ".stl": read_stl, ".off": read_off}.get(ext)
    if reader is None:
        raise ArticulaInputError(f"{path}: unsupported mesh format {ext or '(no extension)'!r}; "
                                 f"use one of {', '.join(MESH_EXTENSIONS)}")
    return reader(path)


# -- shared helpers --------------------------------------------------------------------------------
def read_bytes(path: str) -> bytes:
    """The file's content; a clear error when it is missing or unreadable."""
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise ArticulaInputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ArticulaInputError(f"{path}: is a folder, not a file") from None
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot read ({exc.strerror or exc})") from None


def _numbers(tokens, dtype, path: str, what: str) -> np.ndarray:
    try:
        return np.array(tokens, dtype=bytes).astype(dtype)
    except (ValueError, OverflowError) as exc:
        raise ArticulaInputError(f"{path}: bad {what}: {exc}") from None


def check_finite(vertices: np.ndarray, path: str) -> None:
    """Raise naming the first vertex with a NaN or infinite coordinate."""
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ArticulaInputError(f"{path}: vertex {i} has a non-finite coordinate {vertices[i].tolist()} "
                                 f"({int(bad.sum())} such vertices)")


def _finish(path: str, vertices: np.ndarray, sizes: np.ndarray, corners: np.ndarray) -> PolyMesh:
    """Validate and pack: finite vertices, faces with >= 3 corners and indices in range; drop faces
    that use a vertex twice."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    sizes = np.asarray(sizes, np.int64)
    corners = np.asarray(corners, np.int64)
    check_finite(vertices, path)
    if sizes.size and sizes.min() < 3:
        k = int(np.flatnonzero(sizes < 3)[0])
        raise ArticulaInputError(f"{path}: face {k} has {sizes[k]} corners (at least 3 needed)")
    if corners.size:
        out = (corners < 0) | (corners >= len(vertices))
        if out.any():
            c = int(np.flatnonzero(out)[0])
            k = int(np.searchsorted(np.cumsum(sizes), c, side="right"))
            raise ArticulaInputError(f"{path}: face {k} uses vertex {corners[c]}, but there are only "
                                     f"{len(vertices)} vertices")
        sizes, corners = _drop_degenerate(sizes, corners)
    return PolyMesh(vertices, sizes.astype(np.int32), corners.astype(np.int32))


def _drop_degenerate(sizes: np.ndarray, corners: np.ndarray):
    """Remove faces that use a vertex more than once."""
    if sizes.size and (sizes == sizes[0]).all():     # one face size: a row-wise check
        rows = np.sort(corners.reshape(len(sizes), -1), axis=1)
        bad = (rows[:, 1:] == rows[:, :-1]).any(axis=1)
        if not bad.any():
            return sizes, corners
        return sizes[~bad], corners.reshape(len(sizes), -1)[~bad].reshape(-1)
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    order = np.lexsort((corners, face_of))
    same = (face_of[order][1:] == face_of[order][:-1]) & (corners[order][1:] == corners[order][:-1])
    if not same.any():
        return sizes, corners
    bad_faces = np.zeros(len(sizes), bool)
    bad_faces[face_of[order][1:][same]] = True
    return sizes[~bad_faces], corners[~bad_faces[face_of]]


# -- OBJ ------------------------------------------------------------------------------------------
_SLASH_PART = re.compile(rb"/\S*")
_V_ROWS = re.compile(rb"^v[ \t]([^\n]*)", re.M)
_F_ROWS = re.compile(rb"^f[ \t]([^\n]*)", re.M)
_V_ROWS_INDENTED = re.compile(rb"^[ \t]*v[ \t]+([^\n]*)", re.M)   # slower; only when lines are indented
_F_ROWS_INDENTED = re.compile(rb"^[ \t]*f[ \t]+([^\n]*)", re.M)


def _parse_numbers(text: bytes, dtype, expected):
    """Whitespace-separated numbers at C speed, or None when parsing fails or (``expected`` given) the
    count differs.  (numpy < 2 stops at a bad token with a warning instead of raising: the count or the
    caller's own check catches that.)"""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            out = np.fromstring(text, dtype=dtype, sep=" ")
    except ValueError:
        return None
    return out if expected is None or out.size == expected else None


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
    vertices = _parse_numbers(b" ".join(v_rows), np.float64, 3 * len(v_rows))
    if vertices is None:   # w or colours after x y z, or bad numbers: row by row
        rows = [r.split()[:3] for r in v_rows]
        short = [i for i, r in enumerate(rows) if len(r) < 3]
        if short:
            raise ArticulaInputError(f"{path}: vertex {short[0]} has fewer than 3 coordinates")
        vertices = _numbers(rows, np.float64, path, "vertex coordinate")
    vertices = vertices.reshape(-1, 3)
    f_rows = f_re.findall(data)
    if not f_rows:
        return _finish(path, vertices, np.zeros(0, np.int64), np.zeros(0, np.int64))
    # Faces joined with " 0 " (0 is never a valid OBJ index) so row ends survive number parsing.
    text = _SLASH_PART.sub(b"", b" 0 ".join(f_rows)) + b" 0"
    idx = _parse_numbers(text, np.int64, None)
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
    return _finish(path, vertices, sizes, idx)


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


# -- PLY ------------------------------------------------------------------------------------------
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


@dataclass
class _PlyProperty:
    name: str
    type: str              # numpy type code without byte order
    count_type: str = ""   # non-empty for list properties


def _ply_header(data: bytes, path: str):
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ArticulaInputError(f"{path}: not a PLY file (no 'ply' ... 'end_header' header)")
    nl = data.find(b"\n", end)
    body_start = len(data) if nl < 0 else nl + 1
    fmt, elements = None, []
    for n, raw in enumerate(data[:end].decode("latin-1").splitlines()[1:], 2):
        words = raw.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append((words[1], int(words[2]), []))
            elif words[0] == "property" and words[1] == "list":
                elements[-1][2].append(_PlyProperty(words[4], _PLY_TYPES[words[3]], _PLY_TYPES[words[2]]))
            elif words[0] == "property":
                elements[-1][2].append(_PlyProperty(words[2], _PLY_TYPES[words[1]]))
            else:
                raise ValueError
        except (IndexError, KeyError, ValueError):
            raise ArticulaInputError(f"{path}: bad PLY header line {n}: {raw.strip()!r}") from None
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ArticulaInputError(f"{path}: unknown PLY format {fmt!r}")
    return fmt, elements, body_start


def read_ply(path: str) -> PolyMesh:
    """Stanford PLY, ascii or binary (either byte order): ``vertex`` x/y/z and ``face``
    ``vertex_indices`` (or ``vertex_index``) lists; other elements and properties are skipped."""
    data = read_bytes(path)
    fmt, elements, body = _ply_header(data, path)
    reader = _PlyAscii(data, body, path) if fmt == "ascii" else \
        _PlyBinary(data, body, "<" if fmt == "binary_little_endian" else ">", path)
    vertices = sizes = corners = None
    for name, count, props in elements:
        values = reader.element(name, count, props)
        if name == "vertex":
            missing = [c for c in "xyz" if c not in values]
            if missing:
                raise ArticulaInputError(f"{path}: PLY vertex element has no {'/'.join(missing)} property")
            vertices = np.stack([values[c] for c in "xyz"], axis=1).astype(np.float64)
        elif name == "face":
            key = next((k for k in ("vertex_indices", "vertex_index") if k in values), None)
            if key is None:
                raise ArticulaInputError(f"{path}: PLY face element has no vertex_indices list")
            sizes, corners = values[key]
    if vertices is None:
        raise ArticulaInputError(f"{path}: PLY file has no vertex element")
    if sizes is None:
        sizes, corners = np.zeros(0, np.int64), np.zeros(0, np.int64)
    return _finish(path, vertices, sizes, corners)


class _PlyBinary:
    def __init__(self, data, offset, order, path):
        self.data, self.offset, self.order, self.path = data, offset, order, path

    def _dtype(self, props, list_len=None):
        fields = []
        for p in props:
            if p.count_type:
                fields.append((p.name + "#n", self.order + p.count_type))
                fields.append((p.name, self.order + p.type, (list_len,)))
            else:
                fields.append((p.name, self.order + p.type))
        return np.dtype(fields)

    def _short(self, name, i=None):
        where = f" (record {i})" if i is not None else ""
        return ArticulaInputError(f"{self.path}: PLY file ends inside element {name!r}{where}; truncated?")

    def element(self, name, count, props):
        lists = [p for p in props if p.count_type]
        if not lists:
            dt = self._dtype(props)
            if self.offset + count * dt.itemsize > len(self.data):
                raise self._short(name)
            rec = np.frombuffer(self.data, dt, count, self.offset)
            self.offset += count * dt.itemsize
            return {p.name: rec[p.name] for p in props}
        if len(lists) == 1 and count:
            out = self._uniform(name, count, props, lists[0])
            if out is not None:
                return out
        return self._sequential(name, count, props)

    def _uniform(self, name, count, props, lp):
        """Every record's list has the length of the first one: one structured read."""
        before = sum(np.dtype(p.type).itemsize for p in props[:props.index(lp)])
        ct = np.dtype(self.order + lp.count_type)
        if self.offset + before + ct.itemsize > len(self.data):
            raise self._short(name, 0)
        n = int(np.frombuffer(self.data, ct, 1, self.offset + before)[0])
        dt = self._dtype(props, n)
        if self.offset + count * dt.itemsize > len(self.data):
            return None
        rec = np.frombuffer(self.data, dt, count, self.offset)
        if not (rec[lp.name + "#n"] == n).all():
            return None
        self.offset += count * dt.itemsize
        out = {p.name: rec[p.name] for p in props if not p.count_type}
        out[lp.name] = (np.full(count, n, np.int64), rec[lp.name].reshape(-1).astype(np.int64))
        return out

    def _sequential(self, name, count, props):
        scal = {p.name: [] for p in props if not p.count_type}
        lists = {p.name: ([], []) for p in props if p.count_type}
        data, off = self.data, self.offset
        try:
            for i in range(count):
                for p in props:
                    if p.count_type:
                        ct = np.dtype(self.order + p.count_type)
                        n = int(np.frombuffer(data, ct, 1, off)[0])
                        off += ct.itemsize
                        it = np.dtype(self.order + p.type)
                        lists[p.name][0].append(n)
                        lists[p.name][1].append(np.frombuffer(data, it, n, off))
                        off += n * it.itemsize
                    else:
                        it = np.dtype(self.order + p.type)
                        scal[p.name].append(np.frombuffer(data, it, 1, off)[0])
                        off += it.itemsize
        except ValueError:
            raise self._short(name, i) from None
        self.offset = off
        out = {k: np.array(v) for k, v in scal.items()}
        for k, (n, parts) in lists.items():
            out[k] = (np.array(n, np.int64),
                      np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64))
        return out


class _PlyAscii:
    def __init__(self, data, offset, path):
        self.tokens = data[offset:].split()
        self.pos, self.path = 0, path

    def _take(self, name, n):
        if self.pos + n > len(self.tokens):
            raise ArticulaInputError(f"{self.path}: PLY file ends inside element {name!r}; truncated?")
        out = self.tokens[self.pos:self.pos + n]
        self.pos += n
        return out

    def _num(self, tokens, t, name):
        kind = np.float64 if t.startswith("f") else np.int64
        return _numbers(tokens, kind, self.path, f"value in PLY element {name!r}")

    def element(self, name, count, props):
        lists = [p for p in props if p.count_type]
        if not lists:
            k = len(props)
            table = np.array(self._take(name, count * k)).reshape(count, k)
            return {p.name: self._num(table[:, j], p.type, name) for j, p in enumerate(props)}
        if len(lists) == 1 and count:
            out = self._uniform(name, count, props, lists[0])
            if out is not None:
                return out
        return self._sequential(name, count, props)

    def _uniform(self, name, count, props, lp):
        j = props.index(lp)
        if self.pos + j >= len(self.tokens):
            return None
        try:
            n = int(self.tokens[self.pos + j])
        except ValueError:
            raise ArticulaInputError(f"{self.path}: bad list length in PLY element {name!r} record 0") from None
        width = len(props) - 1 + 1 + n
        if self.pos + count * width > len(self.tokens):
            return None
        table = np.array(self.tokens[self.pos:self.pos + count * width]).reshape(count, width)
        if not (table[:, j] == self.tokens[self.pos + j]).all():
            return None
        self.pos += count * width
        out, col = {}, 0
        for p in props:
            if p.count_type:
                out[p.name] = (np.full(count, n, np.int64),
                               self._num(table[:, col + 1:col + 1 + n].reshape(-1), "i", name))
                col += 1 + n
            else:
                out[p.name] = self._num(table[:, col], p.type, name)
                col += 1
        return out

    def _sequential(self, name, count, props):
        scal = {p.name: [] for p in props if not p.count_type}
        lists = {p.name: ([], []) for p in props if p.count_type}
        for i in range(count):
            for p in props:
                if p.count_type:
                    try:
                        n = int(self._take(name, 1)[0])
                    except ValueError:
                        raise ArticulaInputError(
                            f"{self.path}: bad list length in PLY element {name!r} record {i}") from None
                    lists[p.name][0].append(n)
                    lists[p.name][1].extend(self._take(name, n))
                else:
                    scal[p.name].append(self._take(name, 1)[0])
        out = {p.name: self._num(scal[p.name], p.type, name) for p in props if not p.count_type}
        for k, (n, flat) in lists.items():
            out[k] = (np.array(n, np.int64), self._num(flat, "i", name) if flat else np.zeros(0, np.int64))
        return out


# -- STL ------------------------------------------------------------------------------------------
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
    corners = _numbers(found, np.float64, path, "vertex coordinate").reshape(-1, 3)
    return _weld(path, corners)


def _weld(path, corners):
    corners = np.asarray(corners, np.float64) + 0.0  # + 0.0 turns -0.0 into 0.0 so both weld
    check_finite(corners, path)
    if not len(corners):
        return _finish(path, corners, np.zeros(0, np.int64), np.zeros(0, np.int64))
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
    return _finish(path, corners[np.sort(first)], np.full(len(corners) // 3, 3), inverse)


# -- OFF ------------------------------------------------------------------------------------------
def read_off(path: str) -> PolyMesh:
    """Object File Format: ``OFF`` (or ``COFF``/``NOFF``/``CNOFF``) header, counts, vertex lines
    (first three numbers used), face lines ``n i1 .. in [colour]``.  ``#`` starts a comment."""
    data = read_bytes(path)
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
    except (IndexError, ValueError):
        raise ArticulaInputError(f"{path}: OFF header has no vertex and face counts") from None
    vlines, flines = lines[rest:rest + nv], lines[rest + nv:rest + nv + nf]
    if len(vlines) < nv or len(flines) < nf:
        raise ArticulaInputError(f"{path}: OFF file declares {nv} vertices and {nf} faces but ends early")
    vertices = _parse_numbers(b" ".join(vlines), np.float64, 3 * nv)
    if vertices is None:   # colours after the coordinates, or bad numbers: line by line
        rows = [ln.split()[:3] for ln in vlines]
        if any(len(r) < 3 for r in rows):
            i = next(i for i, r in enumerate(rows) if len(r) < 3)
            raise ArticulaInputError(f"{path}: vertex {i} has fewer than 3 coordinates")
        vertices = _numbers(rows, np.float64, path, "vertex coordinate")
    if not nf:
        return _finish(path, vertices, np.zeros(0, np.int64), np.zeros(0, np.int64))
    k = int(flines[0].split()[0]) if flines[0].split()[0].isdigit() else -1
    flat = _parse_numbers(b" ".join(flines), np.int64, nf * (k + 1)) if k > 0 else None
    if flat is not None and (flat[::k + 1] == k).all():   # every face has k corners and nothing else
        table = flat.reshape(nf, k + 1)
        return _finish(path, vertices, table[:, 0], table[:, 1:].reshape(-1))
    rows = [ln.split() for ln in flines]
    sizes = _numbers([r[0] for r in rows], np.int64, path, "face size")
    for i, (n, r) in enumerate(zip(sizes.tolist(), rows)):
        if len(r) < n + 1:
            raise ArticulaInputError(f"{path}: face {i} declares {n} corners but lists {len(r) - 1}")
    corners = _numbers([t for n, r in zip(sizes.tolist(), rows) for t in r[1:n + 1]], np.int64, path,
                       "face index")
    return _finish(path, vertices, sizes, corners)
