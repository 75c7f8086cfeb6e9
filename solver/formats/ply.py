"""Stanford PLY mesh reader (pure numpy), ascii or binary in either byte order.  The header is read and
the element counts it declares are checked against the file size (:func:`check_ply`) before the file
is read whole."""
from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError
from .bounded import check_size, read_bytes, read_head, size_text
from .polymesh import PolyMesh, finish_mesh, parse_numbers

#: The longest PLY header read (comments included) before ``end_header`` must have appeared.
MAX_HEADER_BYTES = 1 << 20

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
                if elements[-1][1] < 0:
                    raise ValueError
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


def check_ply(path: str):
    """Read and check the header only: a 'ply' ... 'end_header' header within the first
    :data:`MAX_HEADER_BYTES`, element counts that fit the file size, the file within the scan limit.
    Returns ``(format, elements, body offset)``."""
    head, size = read_head(path)
    if not head.startswith(b"ply") or head[3:4] not in (b"\n", b"\r"):
        raise ArticulaInputError(f"{path}: not a PLY file (no 'ply' ... 'end_header' header)")
    if b"end_header" not in head and (size is None or size > len(head)):
        head, size = read_head(path, MAX_HEADER_BYTES)
    fmt, elements, body = _ply_header(head, path)
    if size is not None:
        _check_counts(path, fmt, elements, size - body)
    check_size(path, size)
    return fmt, elements, body


def _check_counts(path, fmt, elements, have):
    """Refuse element counts that need more bytes than the ``have`` bytes after the header: each binary
    record at least its fixed-size properties and list counts, each ascii value at least 2 characters."""
    need = 0
    for name, count, props in elements:
        if fmt == "ascii":
            per = 2 * len(props)
        else:
            per = sum(np.dtype(p.count_type or p.type).itemsize for p in props)
        need += count * per
        if need > have + 1:
            raise ArticulaInputError(f"{path}: the PLY header declares {count} {name!r} records, which need at "
                                     f"least {size_text(need)}, but the file has {size_text(have)} after the "
                                     "header; truncated?")


def read_ply(path: str) -> PolyMesh:
    """Stanford PLY, ascii or binary (either byte order): ``vertex`` x/y/z and ``face``
    ``vertex_indices`` (or ``vertex_index``) lists; other elements and properties are skipped."""
    check_ply(path)
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
    return finish_mesh(path, vertices, sizes, corners)


class _PlyBody:
    """Reads the body element by element.  The element logic is here; subclasses (ascii, binary) supply
    how a whole fixed-width element, a uniform-list element, one value and one list are read."""

    def element(self, name, count, props) -> dict:
        """``{property: values (count,)}``, lists as ``(lengths (count,), items (sum,) int64)``."""
        lists = [p for p in props if p.count_type]
        if not lists:
            return self._fixed(name, count, props)
        if len(lists) == 1 and count:
            out = self._uniform(name, count, props, lists[0])
            if out is not None:
                return out
        return self._sequential(name, count, props)

    def _sequential(self, name, count, props) -> dict:
        """Record by record: the general case (several lists, or lists of varying length)."""
        scal = {p.name: [] for p in props if not p.count_type}
        lists = {p.name: ([], []) for p in props if p.count_type}
        for i in range(count):
            for p in props:
                if p.count_type:
                    n, items = self._list(name, p, i)
                    lists[p.name][0].append(n)
                    lists[p.name][1].append(items)
                else:
                    scal[p.name].append(self._value(name, p, i))
        out = {p.name: self._values(scal[p.name], p.type, name) for p in props if not p.count_type}
        for k, (n, parts) in lists.items():
            out[k] = (np.array(n, np.int64), self._indices(parts, name))
        return out


class _PlyBinary(_PlyBody):
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
        where = f" (record {i + 1})" if i is not None else ""
        return ArticulaInputError(f"{self.path}: PLY file ends inside element {name!r}{where}; truncated?")

    def _fixed(self, name, count, props):
        dt = self._dtype(props)
        if self.offset + count * dt.itemsize > len(self.data):
            raise self._short(name)
        rec = np.frombuffer(self.data, dt, count, self.offset)
        self.offset += count * dt.itemsize
        return {p.name: rec[p.name] for p in props}

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

    def _read(self, type_code, n, name, i):
        it = np.dtype(self.order + type_code)
        try:
            out = np.frombuffer(self.data, it, n, self.offset)
        except ValueError:
            raise self._short(name, i) from None
        self.offset += n * it.itemsize
        return out

    def _value(self, name, p, i):
        return self._read(p.type, 1, name, i)[0]

    def _list(self, name, p, i):
        n = int(self._read(p.count_type, 1, name, i)[0])
        return n, self._read(p.type, n, name, i)

    def _values(self, values, type_code, name):
        return np.array(values)

    def _indices(self, parts, name):
        return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)


class _PlyAscii(_PlyBody):
    def __init__(self, data, offset, path):
        self.tokens = data[offset:].split()
        self.pos, self.path = 0, path

    def _take(self, name, n):
        if self.pos + n > len(self.tokens):
            raise ArticulaInputError(f"{self.path}: PLY file ends inside element {name!r}; truncated?")
        out = self.tokens[self.pos:self.pos + n]
        self.pos += n
        return out

    def _values(self, tokens, type_code, name):
        kind = np.float64 if type_code.startswith("f") else np.int64
        return parse_numbers(tokens, kind, self.path, f"value in PLY element {name!r}")

    def _indices(self, parts, name):
        flat = [t for part in parts for t in part]
        return self._values(flat, "i", name) if flat else np.zeros(0, np.int64)

    def _fixed(self, name, count, props):
        k = len(props)
        table = np.array(self._take(name, count * k)).reshape(count, k)
        return {p.name: self._values(table[:, j], p.type, name) for j, p in enumerate(props)}

    def _uniform(self, name, count, props, lp):
        """Every record's list has the length of the first one: one token table."""
        j = props.index(lp)
        if self.pos + j >= len(self.tokens):
            return None
        try:
            n = int(self.tokens[self.pos + j])
        except ValueError:
            raise self._bad_length(name, 0) from None
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
                               self._values(table[:, col + 1:col + 1 + n].reshape(-1), "i", name))
                col += 1 + n
            else:
                out[p.name] = self._values(table[:, col], p.type, name)
                col += 1
        return out

    def _bad_length(self, name, i):
        return ArticulaInputError(f"{self.path}: bad list length in PLY element {name!r} record {i + 1}")

    def _value(self, name, p, i):
        return self._take(name, 1)[0]

    def _list(self, name, p, i):
        try:     # (a file ending here also reports a bad length: ArticulaInputError is a ValueError)
            n = int(self._take(name, 1)[0])
        except ValueError:
            raise self._bad_length(name, i) from None
        return n, self._take(name, n)
