"""Readers of libigl's plain-text rig formats, as used by public skinning ground-truth data (a mesh,
its skeleton, exact weights and per-pose bone transforms).

* ``.tgf`` skeleton graph: lines ``index x y z`` (1-based joint positions), a ``#`` line, then lines
  ``i j`` (one bone per edge, from joint i to joint j, 1-based), optionally another ``#`` and more lines.
  Returns joints ``(J, 3)`` and bones ``(B, 2)`` (0-based joint indices).
* ``.dmat`` dense matrix: a header line ``cols rows`` then ``rows·cols`` numbers in column-major order.
  (The binary variant, header ``0 0`` followed by a binary block, is not supported.)
* ``.Tmat`` (skinning_gt convention): the stacked ``(4·B, 3)`` transforms of one pose: for bone b rows
  4b…4b+3 form T_b with ``posed = Σ_b w_b [v 1] T_b`` (row vectors), so the world map is
  ``x -> T_b[:3].T x + T_b[3]``.  Returned as ``A (B, 3, 3)``, ``t (B, 3)`` with x -> A x + t.

All readers raise :class:`ArticulaInputError` naming the file and the line or count that is wrong.
Units are those of the file.  The first line is checked (and a ``.dmat``'s declared size against the file
size) and the file size against ``bounded.MAX_SCAN_BYTES`` before a file is read whole.
"""
import numpy as np

from articula.solver.errors import ArticulaInputError
from articula.solver.formats.bounded import check_size, read_bytes, read_head, size_text


def _read_lines(path, numbers: int):
    """The file's lines, after checking that its first non-empty line holds ``numbers`` numbers and that
    it is within the size limit."""
    head, size = read_head(path)
    for lineno, line in enumerate(head.decode("utf-8", "replace").splitlines()[:-1] or [""], 1):
        if line.split() and not line.split()[0].startswith("#"):
            _floats(path, lineno, line.split(), numbers)
            break
    check_size(path, size, what="a single rig file", hint="split it")
    return read_bytes(path).decode("utf-8", errors="replace").splitlines()


def _floats(path, lineno, tokens, n):
    try:
        vals = [float(t) for t in tokens[:n]]
    except ValueError:
        raise ArticulaInputError(f"{path}, line {lineno}: expected {n} numbers, got {' '.join(tokens)!r}") from None
    if len(vals) < n:
        raise ArticulaInputError(f"{path}, line {lineno}: expected {n} numbers, got {len(vals)}")
    return vals


def read_tgf(path):
    """``(joints (J, 3) float64, bones (B, 2) int64)`` of a ``.tgf`` file (module docstring)."""
    joints, bones, section = [], [], 0
    for lineno, line in enumerate(_read_lines(path, 4), 1):
        tok = line.split()
        if not tok:
            continue
        if tok[0].startswith("#"):
            section += 1
            continue
        if section == 0:
            idx, x, y, z = _floats(path, lineno, tok, 4)
            if int(idx) != len(joints) + 1:
                raise ArticulaInputError(f"{path}, line {lineno}: joint index {int(idx)}, expected {len(joints) + 1}")
            joints.append((x, y, z))
        elif section == 1:
            i, j = (int(v) for v in _floats(path, lineno, tok, 2))
            bones.append((i - 1, j - 1))
    joints = np.array(joints, dtype=np.float64).reshape(-1, 3)
    bones = np.array(bones, dtype=np.int64).reshape(-1, 2)
    if not len(joints) or not len(bones):
        raise ArticulaInputError(f"{path}: expected joints and bones (edges), got {len(joints)} and {len(bones)}")
    bad = np.flatnonzero((bones < 0).any(1) | (bones >= len(joints)).any(1))
    if len(bad):
        raise ArticulaInputError(f"{path}: bone {bad[0] + 1} refers to joint {bones[bad[0]] + 1}, outside 1..{len(joints)}")
    return joints, bones


def read_dmat(path):
    """The ``(rows, cols)`` float64 matrix of an ASCII ``.dmat`` file."""
    first, size = read_head(path, 256)
    first = first.split(b"\n", 1)[0].decode("utf-8", "replace")
    if not first.strip():
        raise ArticulaInputError(f"{path}: empty file")
    try:
        cols, rows = int(first.split()[0]), int(first.split()[1])
        if cols < 0 or rows < 0:
            raise ValueError
    except (ValueError, IndexError):
        raise ArticulaInputError(f"{path}, line 1: expected the header 'cols rows', got {first!r}") from None
    if cols == 0 and rows == 0:
        raise ArticulaInputError(f"{path}: binary .dmat is not supported (save it as ASCII)")
    if size is not None and 2 * rows * cols > size:
        raise ArticulaInputError(f"{path}: header says {rows} x {cols} values, which need at least "
                                 f"{size_text(2 * rows * cols)}, but the file has {size_text(size)}")
    lines = _read_lines(path, 2)
    try:
        values = np.array(" ".join(lines[1:]).split(), dtype=np.float64)
    except ValueError:
        raise ArticulaInputError(f"{path}: non-numeric value after the header") from None
    if values.size != rows * cols:
        raise ArticulaInputError(f"{path}: header says {rows} x {cols} = {rows * cols} values, found {values.size}")
    return values.reshape(cols, rows).T.copy()


def read_tmat(path, num_bones=None):
    """``(A (B, 3, 3), t (B, 3))`` of a ``.Tmat`` file (module docstring); ``num_bones`` checks B."""
    rows = [_floats(path, k, line.split(), 3) for k, line in enumerate(_read_lines(path, 3), 1) if line.split()]
    T = np.array(rows, dtype=np.float64).reshape(-1, 3)
    if len(T) % 4 or not len(T):
        raise ArticulaInputError(f"{path}: expected 4 rows per bone, got {len(T)} rows")
    B = len(T) // 4
    if num_bones is not None and B != num_bones:
        raise ArticulaInputError(f"{path}: {B} bone transforms, the skeleton has {num_bones} bones")
    T = T.reshape(B, 4, 3)
    return np.swapaxes(T[:, :3], 1, 2).copy(), T[:, 3].copy()
