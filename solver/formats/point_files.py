"""Point-cloud files: one frame per file (PLY / XYZ / NPY), and the point-sequence cache (``.npz``) that
holds every frame of an imported recording for the Blender object to play back (docs/import_depth.md).

Points are in the depth sensor's frame: x right, y down, z forward, metres.

A :class:`PointSequence` holds every frame concatenated: ``points`` (N, 3) float32, ``offsets`` (F + 1,)
int64 so frame k is ``points[offsets[k]:offsets[k + 1]]``, optional ``normals`` (N, 3) float32 and
``colors`` (N, 3) float32 in [0, 1], ``world_from_sensor`` (4, 4) and the frame names.

Cache file (``.npz``, uncompressed so loading is a plain read), format "articula-points/1":

=====================  ============  =====================================================
key                    shape         meaning
=====================  ============  =====================================================
``format``             str           "articula-points/1"
``points``             (N, 3) f4     all frames, sensor frame, metres
``offsets``            (F+1,) i8     frame k = rows offsets[k]:offsets[k+1]
``normals``            (N, 3) f4     optional, unit, facing the sensor
``colors``             (N, 3) f4     optional, linear 0..1 as read
``world_from_sensor``  (4, 4) f8     sensor frame -> world (Z up)
``floor``              (4,) f8       optional fitted floor (nx, ny, nz, d), sensor frame
``intrinsics``         (6,) f8       optional width, height, fx, fy, cx, cy
``frame_names``        (F,) str      source file of every frame
=====================  ============  =====================================================
"""
from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np

from ..errors import ArticulaInputError
from .atomic import written_through
from .bounded import all_numbers, check_size, complete_lines, read_bytes, read_head
from .ply import check_ply, read_ply

FORMAT = "articula-points/1"
CLOUD_EXTENSIONS = (".ply", ".xyz", ".npy", ".txt")


# ------------------------------------------------------------------------------------ frame files

def read_point_file(path: str):
    """One point-cloud frame: ``.npy`` (K, 3) or (K, 6) (xyz + rgb, 0..1 or 0..255), ``.xyz``/``.txt``
    (whitespace columns, same layouts) or ``.ply`` (vertex x/y/z).  Returns ``(points (K, 3) float32,
    colors (K, 3) float32 in 0..1 or None)``; NaN/inf coordinates are refused, naming the row (NPY, from
    1), line (XYZ) or vertex (PLY, from 1).  Files are checked from their first bytes and size first."""
    arr = _read_array(path)
    if arr.ndim != 2 or arr.shape[1] not in (3, 6) or not np.issubdtype(arr.dtype, np.number):
        raise ArticulaInputError(f"{path}: expected a (K, 3) or (K, 6) array of numbers, got shape "
                                 f"{arr.shape} {arr.dtype}")
    pts = arr[:, :3].astype(np.float64)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise ArticulaInputError(f"{path}: {len(rows)} point(s) with NaN/inf coordinates "
                                 f"(first at {_where(path, int(rows[0]))})")
    colors = None
    if arr.shape[1] == 6:
        colors = arr[:, 3:6].astype(np.float32)
        if not np.isfinite(colors).all():
            raise ArticulaInputError(f"{path}: NaN/inf colours")
        if colors.max(initial=0) > 1.0:
            colors /= 255.0
    return pts.astype(np.float32), colors


def _where(path: str, row: int) -> str:
    """Where point ``row`` (from 0) is in the file, for messages."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".ply":
        return f"vertex {row + 1}"
    if ext == ".npy":
        return f"row {row + 1}"
    return f"line {_data_lines(read_bytes(path))[row][0]}"


def _data_lines(data: bytes) -> list:
    """``[(line number from 1, tokens)]`` of the lines of XYZ text holding numbers (not comments)."""
    out = []
    for n, line in enumerate(data.splitlines(), 1):
        tokens = line.split(b"#", 1)[0].split()
        if tokens:
            out.append((n, tokens))
    return out


def _read_array(path: str) -> np.ndarray:
    """The file's numbers as a 2-D array (rows = points), by extension."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in CLOUD_EXTENSIONS:
        raise ArticulaInputError(f"{path}: unknown point-cloud format {ext!r}")
    if ext == ".ply":
        return np.asarray(read_ply(path).vertices)
    if ext == ".npy":
        return _read_npy(path)
    return _read_xyz(path)


def check_point_file(path: str) -> None:
    """Refuse a point-cloud file from its first bytes and size (format, declared size, the size
    limit) without reading it, so a list of frames can be checked before any is read."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in CLOUD_EXTENSIONS:
        raise ArticulaInputError(f"{path}: unknown point-cloud format {ext!r}")
    if ext == ".ply":
        check_ply(path)
    elif ext == ".npy":
        _read_npy(path, check_only=True)
    else:
        _check_xyz(path)


def _read_npy(path: str, check_only: bool = False):
    """A .npy array: the magic and header are checked and the array mapped (not read) until its shape,
    type and size are known to be usable."""
    head, size = read_head(path, 8)
    if not head.startswith(b"\x93NUMPY"):
        raise ArticulaInputError(f"{path}: not a NumPy .npy file (no \\x93NUMPY signature)")
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except ValueError as exc:
        why = "it holds Python objects, not numbers" if "object" in str(exc) or "pickle" in str(exc) else \
            "truncated or malformed" if "mmap length" in str(exc) else str(exc)
        raise ArticulaInputError(f"{path}: cannot read point cloud ({why})") from None
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot read point cloud ({exc.strerror or exc})") from None
    if arr.ndim == 2 and arr.shape[1] in (3, 6):
        check_size(path, arr.nbytes, what="a single point-cloud frame", hint="downsample or split it")
        return None if check_only else np.array(arr)
    return arr


def _read_xyz(path: str) -> np.ndarray:
    """Whitespace-separated columns (``#`` comments); the first number line is checked before the file is
    read, and a bad line is named by its number."""
    _check_xyz(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # empty file -> refused by the shape check
            return np.loadtxt(path, dtype=np.float64, ndmin=2, comments="#")
    except (OSError, ValueError) as exc:
        lines = _data_lines(read_bytes(path, what="a single point-cloud frame", hint="downsample or split it"))
        width = len(lines[0][1]) if lines else 0
        n = next((n for n, t in lines if len(t) != width or not all_numbers(t)), None)
        if n is None:
            raise ArticulaInputError(f"{path}: cannot read point cloud ({exc})") from None
        raise ArticulaInputError(f"{path}, line {n}: cannot read point cloud (expected {width} numbers per "
                                 "line)") from None


def _check_xyz(path: str) -> None:
    """The first number line of an XYZ file holds 3 or 6 numbers; the file is within the size limit."""
    head, size = read_head(path)
    first = _data_lines(b"\n".join(complete_lines(head, size is not None and size <= len(head))))[:1]
    if b"\0" in head or (first and (len(first[0][1]) not in (3, 6) or not all_numbers(first[0][1]))):
        n = first[0][0] if first else 1
        raise ArticulaInputError(f"{path}, line {n}: not a point-cloud text file (expected 3 or 6 numbers "
                                 "per line: x y z [r g b])")
    check_size(path, size, what="a single point-cloud frame", hint="downsample or split it")



# -------------------------------------------------------------------------------- sequence cache

@dataclasses.dataclass
class PointSequence:
    """Every frame of a recording, concatenated (see the module docstring for the arrays)."""
    points: np.ndarray
    offsets: np.ndarray
    world_from_sensor: np.ndarray              # (4, 4) sensor frame -> world (Z up)
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    floor: tuple | None = None                 # (normal (3,), d), sensor frame
    intrinsics: tuple | None = None            # (width, height, fx, fy, cx, cy)
    frame_names: list = dataclasses.field(default_factory=list)
    notes: list = dataclasses.field(default_factory=list)
    timings: dict = dataclasses.field(default_factory=dict)

    @property
    def frame_count(self) -> int:
        return len(self.offsets) - 1

    def frame(self, k: int) -> slice:
        """Rows of frame ``k`` in ``points`` (and ``normals``, ``colors``)."""
        return slice(int(self.offsets[k]), int(self.offsets[k + 1]))

    @classmethod
    def from_frames(cls, frames, **kw) -> "PointSequence":
        """Concatenate per-frame results (objects with ``points``, ``normals``, ``colors`` arrays or
        None, e.g. :class:`solver.depth.frames.FramePoints`); normals/colours only when every frame has
        them."""
        counts = [len(f.points) for f in frames]
        offsets = np.zeros(len(frames) + 1, np.int64)
        np.cumsum(counts, out=offsets[1:])

        def cat(attr):
            vals = [getattr(f, attr) for f in frames]
            if any(v is None for v in vals):
                return None
            return np.concatenate(vals).astype(np.float32) if vals else np.zeros((0, 3), np.float32)

        points = cat("points")
        return cls(points=np.zeros((0, 3), np.float32) if points is None else points, offsets=offsets,
                   normals=cat("normals"), colors=cat("colors"), **kw)

    def save(self, path: str) -> None:
        """Write the cache atomically (a temporary file renamed into place)."""
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        tmp = f"{path}.part{os.getpid()}.npz"
        with written_through(path, tmp, "point cache"):
            np.savez(tmp, **self._arrays())

    def _arrays(self) -> dict:
        data = {"format": np.array(FORMAT), "points": self.points.astype(np.float32),
                "offsets": self.offsets.astype(np.int64),
                "world_from_sensor": np.asarray(self.world_from_sensor, np.float64),
                "frame_names": np.array([os.path.basename(n) for n in self.frame_names], dtype=str)}
        if self.normals is not None:
            data["normals"] = self.normals.astype(np.float32)
        if self.colors is not None:
            data["colors"] = self.colors.astype(np.float32)
        if self.floor is not None:
            data["floor"] = np.r_[np.asarray(self.floor[0], float), float(self.floor[1])]
        if self.intrinsics is not None:
            data["intrinsics"] = np.asarray(self.intrinsics, np.float64)
        return data

    @classmethod
    def load(cls, path: str) -> "PointSequence":
        """Read a cache written by :meth:`save`; a clear error for other files."""
        try:
            with np.load(path, allow_pickle=False) as z:
                fmt = str(z["format"]) if "format" in z.files else ""
                if fmt != FORMAT:
                    raise ArticulaInputError(f"{path}: not an Articula point cache (format {fmt!r})")
                get = lambda k: z[k] if k in z.files else None  # noqa: E731
                floor = get("floor")
                return cls(points=z["points"], offsets=z["offsets"], normals=get("normals"),
                           colors=get("colors"), world_from_sensor=z["world_from_sensor"],
                           floor=None if floor is None else (floor[:3], float(floor[3])),
                           intrinsics=None if get("intrinsics") is None else tuple(get("intrinsics")),
                           frame_names=[str(s) for s in z["frame_names"]])
        except ArticulaInputError:
            raise
        except (OSError, ValueError, KeyError) as exc:
            raise ArticulaInputError(f"{path}: cannot read point cache ({exc})") from exc
