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
from .ply import read_ply

FORMAT = "articula-points/1"
CLOUD_EXTENSIONS = (".ply", ".xyz", ".npy", ".txt")


# ------------------------------------------------------------------------------------ frame files

def read_point_file(path: str):
    """One point-cloud frame: ``.npy`` (K, 3) or (K, 6) (xyz + rgb, 0..1 or 0..255), ``.xyz``/``.txt``
    (whitespace columns, same layouts) or ``.ply`` (vertex x/y/z).  Returns ``(points (K, 3) float32,
    colors (K, 3) float32 in 0..1 or None)``; NaN/inf coordinates are refused, naming the row."""
    arr = _read_array(path)
    if arr.ndim != 2 or arr.shape[1] not in (3, 6) or not np.issubdtype(arr.dtype, np.number):
        raise ArticulaInputError(f"{path}: expected a (K, 3) or (K, 6) array of numbers, got shape "
                                 f"{arr.shape} {arr.dtype}")
    pts = arr[:, :3].astype(np.float64)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise ArticulaInputError(f"{path}: {len(rows)} point(s) with NaN/inf coordinates "
                                 f"(first at row {int(rows[0])})")
    colors = None
    if arr.shape[1] == 6:
        colors = arr[:, 3:6].astype(np.float32)
        if not np.isfinite(colors).all():
            raise ArticulaInputError(f"{path}: NaN/inf colours")
        if colors.max(initial=0) > 1.0:
            colors /= 255.0
    return pts.astype(np.float32), colors


def _read_array(path: str) -> np.ndarray:
    """The file's numbers as a 2-D array (rows = points), by extension."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in CLOUD_EXTENSIONS:
        raise ArticulaInputError(f"{path}: unknown point-cloud format {ext!r}")
    try:
        if ext == ".npy":
            return np.asarray(np.load(path, allow_pickle=False))
        if ext == ".ply":
            return np.asarray(read_ply(path).vertices)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # empty file -> refused by the shape check
            return np.loadtxt(path, dtype=np.float64, ndmin=2, comments="#")
    except ArticulaInputError:
        raise
    except (OSError, ValueError) as exc:
        raise ArticulaInputError(f"{path}: cannot read point cloud ({exc})") from exc


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
        try:
            np.savez(tmp, **self._arrays())
            os.replace(tmp, path)
        except OSError as exc:
            if os.path.exists(tmp):
                os.remove(tmp)
            raise ArticulaInputError(f"{path}: cannot write point cache ({exc.strerror or exc})") from exc

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
