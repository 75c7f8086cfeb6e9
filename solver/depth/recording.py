"""Point-cloud sequences: reading depth recordings and point-cloud files frame by frame, processing
them (``depth_processing``) and the on-disk cache the Blender object plays back.

A :class:`PointSequence` holds every frame concatenated: ``points`` (N, 3) float32 in the sensor
frame (x right, y down, z forward, metres), ``offsets`` (F + 1,) int64 so frame k is
``points[offsets[k]:offsets[k + 1]]``, optional ``normals`` (N, 3) float32 and ``colors`` (N, 3)
float32 in [0, 1], ``world_from_sensor`` (4, 4) and the frame names.

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
import re
import time

import numpy as np

from . import frames as dp
from ..errors import ArticulaInputError

FORMAT = "articula-points/1"
DEPTH_EXTENSIONS = (".png", ".exr")
CLOUD_EXTENSIONS = (".ply", ".xyz", ".npy", ".txt")
COLOR_EXTENSIONS = (".png", ".jpg", ".jpeg")
_CHUNK = 8  # consecutive depth frames decoded and processed together by one pool thread


# ----------------------------------------------------------------------------------------- files

def _natural_key(name: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def list_frames(directory: str, extensions) -> list[str]:
    """Files of ``directory`` with one of ``extensions``, in natural order (frame_2 before frame_10).
    Hidden files and ``background.*`` / ``intrinsics.*`` are not frames."""
    if not directory or not os.path.isdir(directory):
        raise ArticulaInputError(f"{directory or '(no folder given)'}: not a folder")
    try:
        names = os.listdir(directory)
    except OSError as exc:
        raise ArticulaInputError(f"{directory}: cannot list folder ({exc.strerror or exc})") from exc
    frames = [n for n in names if os.path.splitext(n)[1].lower() in extensions and not n.startswith(".")
              and os.path.splitext(n)[0].lower() not in ("background", "intrinsics")]
    if not frames:
        raise ArticulaInputError(f"{directory}: no frames found (expected {', '.join(extensions)} files)")
    return [os.path.join(directory, n) for n in sorted(frames, key=_natural_key)]


def read_depth_png(path: str) -> np.ndarray:
    """A 16-bit grayscale depth PNG -> (H, W) uint16 raw values; 8-bit files are refused."""
    from ..formats.png16 import read_png16
    raw = read_png16(path)
    if raw.dtype != np.uint16:
        raise ArticulaInputError(f"{path}: 8-bit PNG; depth frames must be 16-bit grayscale "
                                 "(an 8-bit image cannot hold millimetre depths)")
    return raw


def read_point_file(path: str):
    """One point-cloud frame: ``.npy`` (K, 3) or (K, 6) (xyz + rgb, 0..1 or 0..255), ``.xyz``/``.txt``
    (whitespace columns, same layouts) or ``.ply`` (vertex x/y/z).  Returns ``(points (K, 3) float32,
    colors (K, 3) float32 in 0..1 or None)``; NaN/inf coordinates are refused, naming the row."""
    ext = os.path.splitext(path)[1].lower()
    colors = None
    try:
        if ext == ".npy":
            arr = np.load(path, allow_pickle=False)
        elif ext in (".xyz", ".txt"):
            import warnings
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # empty file -> handled below
                arr = np.loadtxt(path, dtype=np.float64, ndmin=2, comments="#")
        elif ext == ".ply":
            from ..formats.meshes import read_ply
            arr = read_ply(path).vertices
        else:
            raise ArticulaInputError(f"{path}: unknown point-cloud format {ext!r}")
    except ArticulaInputError:
        raise
    except (OSError, ValueError) as exc:
        raise ArticulaInputError(f"{path}: cannot read point cloud ({exc})") from exc
    arr = np.asarray(arr)
    if arr.ndim != 2 or arr.shape[1] not in (3, 6) or not np.issubdtype(arr.dtype, np.number):
        raise ArticulaInputError(f"{path}: expected a (K, 3) or (K, 6) array of numbers, got shape "
                                 f"{arr.shape} {arr.dtype}")
    pts = arr[:, :3].astype(np.float64)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise ArticulaInputError(f"{path}: {len(rows)} point(s) with NaN/inf coordinates "
                                 f"(first at row {int(rows[0])})")
    if arr.shape[1] == 6:
        colors = arr[:, 3:6].astype(np.float32)
        if not np.isfinite(colors).all():
            raise ArticulaInputError(f"{path}: NaN/inf colours")
        if colors.max(initial=0) > 1.0:
            colors /= 255.0
    return pts.astype(np.float32), colors


# ------------------------------------------------------------------------------------- sequence

@dataclasses.dataclass
class PointSequence:
    points: np.ndarray
    offsets: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    world_from_sensor: np.ndarray = dataclasses.field(default_factory=lambda: dp.world_from_sensor(None))
    floor: tuple | None = None
    intrinsics: tuple | None = None            # (width, height, fx, fy, cx, cy)
    frame_names: list = dataclasses.field(default_factory=list)
    notes: list = dataclasses.field(default_factory=list)
    timings: dict = dataclasses.field(default_factory=dict)

    @property
    def frame_count(self) -> int:
        return len(self.offsets) - 1

    def frame(self, k: int) -> slice:
        return slice(int(self.offsets[k]), int(self.offsets[k + 1]))

    @classmethod
    def from_frames(cls, frames, **kw) -> "PointSequence":
        """Concatenate a list of :class:`~.depth_processing.FramePoints`."""
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

    # -- cache -------------------------------------------------------------------------------
    def save(self, path: str) -> None:
        """Write the cache atomically (a temporary file renamed into place)."""
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
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        tmp = f"{path}.part{os.getpid()}.npz"
        try:
            np.savez(tmp, **data)
            os.replace(tmp, path)
        except OSError as exc:
            if os.path.exists(tmp):
                os.remove(tmp)
            raise ArticulaInputError(f"{path}: cannot write point cache ({exc.strerror or exc})") from exc

    @classmethod
    def load(cls, path: str) -> "PointSequence":
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


# ---------------------------------------------------------------------------------- depth input

@dataclasses.dataclass
class DepthFrame:
    """One depth frame to import: ``name`` (for messages) and ``load() -> (H, W)`` raw depth (uint16
    PNG values, scaled by ``depth_scale``) or metres (``metres=True``, e.g. EXR from Blender).
    ``png``: the PNG file path when the frame is a PNG (then frames are decoded in batches)."""
    name: str
    load: object
    metres: bool = False
    png: str | None = None


def png_frames(paths) -> list[DepthFrame]:
    return [DepthFrame(p, (lambda p=p: read_depth_png(p)), png=p) for p in paths]


class _Prefetch:
    """Raw frames decoded ahead, consecutive PNG frames in batches (``png16.read_png16_many``
    unfilters a batch of equal-size frames together, faster on Paeth/Average-filtered files)."""

    def __init__(self, frames, batch: int = 8, start: int = -1):
        self.frames, self.batch, self.ready, self.last = frames, batch, {}, start - 1

    def raw(self, k: int) -> np.ndarray:
        sequential, self.last = k == self.last + 1, k
        if k in self.ready:
            return self.ready.pop(k)
        f = self.frames[k]
        if f.png is None:
            return f.load()
        from ..formats.png16 import read_png16_many
        ahead = [k]
        if sequential:  # reading in order: decode the next frames now, together
            for j in range(k + 1, min(k + self.batch, len(self.frames))):
                if not self.frames[j].png or j in self.ready:
                    break
                ahead.append(j)
        arrays = read_png16_many([self.frames[j].png for j in ahead], batch=self.batch)
        for j, a in zip(ahead, arrays):
            if a.dtype != np.uint16:
                if j == k:
                    raise ArticulaInputError(f"{self.frames[j].png}: 8-bit PNG; depth frames must be 16-bit "
                                             "grayscale (an 8-bit image cannot hold millimetre depths)")
                break  # reported when its turn comes
            self.ready[j] = a
        return self.ready.pop(k)


def _no_progress(fraction, text=""):
    pass


def _frame_metres(frame: DepthFrame, opts: dp.DepthOptions, shape, first_name, raw=None) -> np.ndarray:
    raw = frame.load() if raw is None else raw
    if raw.ndim != 2:
        raise ArticulaInputError(f"{frame.name}: expected a single-channel depth image, got shape {raw.shape}")
    if raw.shape != shape:
        raise ArticulaInputError(f"{frame.name}: {raw.shape[1]}x{raw.shape[0]} pixels, but "
                                 f"{os.path.basename(first_name)} is {shape[1]}x{shape[0]}; all frames "
                                 "must have the same size")
    if frame.metres:
        return dp.depth_in_metres(np.asarray(raw, np.float32), dataclasses.replace(opts, depth_scale=1.0))
    return dp.depth_in_metres(raw, opts)


def _pick(n: int, k: int) -> list[int]:
    """k indices spread evenly over range(n)."""
    return sorted(set(np.linspace(0, n - 1, min(k, n)).round().astype(int).tolist()))


def import_depth(frames: list, intr, opts: dp.DepthOptions, progress=_no_progress,
                 background: DepthFrame | None = None, colors: list | None = None) -> PointSequence:
    """Depth frames -> :class:`PointSequence`.

    ``intr``: :class:`~.camera.Intrinsics`; when the frames have another size with the same aspect
    ratio the intrinsics are rescaled (noted in ``notes``), otherwise the import fails.
    ``background``: a frame of the empty scene for background subtraction; without one the per-pixel
    median of ``opts.background_frames`` frames spread evenly over the recording is used (right
    wherever the subject covers a pixel in fewer than half of those frames, i.e. when it moves).
    ``colors``: optional list (one per frame) of callables returning (H, W, 3) float images.
    Frames are decoded and processed in chunks of 8 by ``opts.workers`` threads (0 = up to 4).
    The floor plane is fitted once, on points pooled from up to 8 frames spread over the recording
    (after the range clip, before background subtraction: the floor is part of the static scene), and
    points on or below it are removed from every frame.
    """
    opts.validate()
    if not frames:
        raise ArticulaInputError("no depth frames to import")
    if colors is not None and len(colors) != len(frames):
        raise ArticulaInputError(f"{len(colors)} colour frames for {len(frames)} depth frames; "
                                 "the counts must match")
    t_decode = 0.0
    t0 = time.perf_counter()
    prefetch = _Prefetch(frames)  # for the set-up frames (background, floor), read out of order
    first_raw = prefetch.raw(0)
    prefetch.ready[0] = first_raw
    t_decode += time.perf_counter() - t0
    shape = tuple(first_raw.shape[:2])
    notes = []
    if (intr.height, intr.width) != shape:
        if abs(shape[1] / shape[0] - intr.width / intr.height) > 1e-6:
            raise ArticulaInputError(f"{frames[0].name}: {shape[1]}x{shape[0]} pixels, but the intrinsics "
                                     f"{intr.name!r} are for {intr.width}x{intr.height}")
        intr = intr.with_resolution(shape[1], shape[0])
        notes.append(f"intrinsics rescaled to the frames' {shape[1]}x{shape[0]} pixels")
    rays = dp.pixel_rays(intr)
    decoded = {}

    def metres(k):
        nonlocal t_decode
        if k not in decoded:
            t = time.perf_counter()
            decoded[k] = _frame_metres(frames[k], opts, shape, frames[0].name, prefetch.raw(k))
            t_decode += time.perf_counter() - t
        return decoded[k]

    bg = None
    if opts.subtract_background:
        progress(0.0, "background")
        if background is not None:
            bg = _frame_metres(background, opts, shape, frames[0].name)
        else:
            picked = _pick(len(frames), opts.background_frames)
            bg = dp.median_background([metres(k) for k in picked])
            notes.append(f"background = per-pixel median of {len(picked)} frames spread over the recording")
    floor = None
    if opts.remove_floor:
        progress(0.02, "floor")
        rng = np.random.default_rng(opts.seed)
        pool = []
        for k in _pick(len(frames), 8):
            z = metres(k)
            grid = dp.backproject_grid(z, rays)
            keep = dp.frame_mask(z, grid, opts)  # the floor is static: fit it before background removal
            pts = grid[keep]
            if len(pts) > 5000:
                pts = pts[rng.choice(len(pts), 5000, replace=False)]
            pool.append(pts)
        pool = np.concatenate(pool) if pool else np.zeros((0, 3), np.float32)
        plane, inl = dp.ransac_plane(pool, opts.floor_tolerance, opts.floor_iterations, opts.seed,
                                     max_tilt_deg=opts.floor_max_tilt)
        if plane is not None and inl.sum() >= max(50, opts.floor_min_fraction * len(pool)):
            floor = plane
            notes.append(f"floor found {plane[1]:.3f} m below the camera "
                         f"({100 * inl.mean():.0f}% of the sampled points)")
        else:
            notes.append("no floor found (no plane within "
                         f"{opts.floor_max_tilt:g} deg of level holding {100 * opts.floor_min_fraction:g}% of the points)")
    def run_chunk(ks):
        """Decode and process consecutive frames ks (runs in a pool thread; no shared state written)."""
        pref = _Prefetch(frames, start=ks[0])
        done, t_dec, t_pro = [], 0.0, 0.0
        for k in ks:
            t = time.perf_counter()
            z = decoded[k] if k in decoded else _frame_metres(frames[k], opts, shape, frames[0].name, pref.raw(k))
            col = colors[k]() if colors is not None else None
            t1 = time.perf_counter()
            done.append(dp.process_depth(z, rays, opts, bg, floor, col))
            t_dec, t_pro = t_dec + t1 - t, t_pro + time.perf_counter() - t1
        return done, t_dec, t_pro

    n = len(frames)
    t_setup = time.perf_counter() - t0
    t_frames = time.perf_counter()
    chunks = [list(range(i, min(i + _CHUNK, n))) for i in range(0, n, _CHUNK)]
    workers = opts.workers or min(4, os.cpu_count() or 1)
    out = []
    t_proc = 0.0

    def collect(result, ks):
        nonlocal t_decode, t_proc
        done, t_dec, t_pro = result
        out.extend(done)
        t_decode, t_proc = t_decode + t_dec, t_proc + t_pro
        progress(0.05 + 0.95 * (ks[-1] + 1) / n, f"frame {ks[-1] + 1}/{n}")

    if workers <= 1 or len(chunks) == 1:
        for ks in chunks:
            collect(run_chunk(ks), ks)
    else:  # numpy and zlib release the GIL: frames are decoded and processed in parallel, kept in order
        from concurrent.futures import ThreadPoolExecutor
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(run_chunk, ks) for ks in chunks]
            try:
                for fut, ks in zip(futures, chunks):
                    collect(fut.result(), ks)
            except BaseException:
                for fut in futures:
                    fut.cancel()
                raise
    progress(1.0, "done")
    t_frames = time.perf_counter() - t_frames
    t = time.perf_counter()
    seq = PointSequence.from_frames(out, world_from_sensor=dp.world_from_sensor(floor), floor=floor,
                                    intrinsics=(intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy),
                                    frame_names=[f.name for f in frames], notes=notes)
    # setup/frames/concatenate: wall seconds; decode/processing: seconds summed over the worker threads
    seq.timings = {"setup": t_setup, "frames": t_frames, "concatenate": time.perf_counter() - t,
                   "decode": t_decode, "processing": t_proc, "workers": min(workers, len(chunks))}
    return seq


def import_clouds(paths: list, opts: dp.DepthOptions, progress=_no_progress, intr=None) -> PointSequence:
    """Point-cloud files (sensor frame: x right, y down, z forward) -> :class:`PointSequence`.

    Range clip on z, floor removal (plane fitted on points pooled from up to 8 frames), voxel
    downsampling and PCA normals as for depth frames; background subtraction needs depth images and
    is not applied (a note says so)."""
    opts.validate()
    if not paths:
        raise ArticulaInputError("no point-cloud frames to import")
    notes = []
    if opts.subtract_background:
        notes.append("background subtraction needs depth images; not applied to point clouds")
    t_decode = 0.0
    cache = {}

    def read(k):
        nonlocal t_decode
        if k not in cache:
            t = time.perf_counter()
            cache[k] = read_point_file(paths[k])
            t_decode += time.perf_counter() - t
        return cache[k]

    floor = None
    if opts.remove_floor:
        rng = np.random.default_rng(opts.seed)
        pool = []
        for k in _pick(len(paths), 8):
            p = read(k)[0]
            p = p[(p[:, 2] >= opts.depth_min) & (p[:, 2] <= opts.depth_max)]
            if len(p) > 5000:
                p = p[rng.choice(len(p), 5000, replace=False)]
            pool.append(p)
        pool = np.concatenate(pool)
        plane, inl = dp.ransac_plane(pool, opts.floor_tolerance, opts.floor_iterations, opts.seed,
                                     max_tilt_deg=opts.floor_max_tilt)
        if plane is not None and inl.sum() >= max(50, opts.floor_min_fraction * len(pool)):
            floor = plane
            notes.append(f"floor found {plane[1]:.3f} m below the sensor origin")
        else:
            notes.append("no floor found")
    out = []
    t_proc = 0.0
    for k in range(len(paths)):
        progress(k / len(paths), f"frame {k + 1}/{len(paths)}")
        pts, col = read(k)
        cache.pop(k, None)
        t = time.perf_counter()
        out.append(dp.process_cloud(pts, opts, floor, col))
        t_proc += time.perf_counter() - t
    if any(f.colors is None for f in out) and any(f.colors is not None for f in out):
        notes.append("some frames have no colours; colours dropped")
        for f in out:
            f.colors = None
    progress(1.0, "done")
    intr_t = None if intr is None else (intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy)
    seq = PointSequence.from_frames(out, world_from_sensor=dp.world_from_sensor(floor), floor=floor,
                                    intrinsics=intr_t, frame_names=list(paths), notes=notes)
    seq.timings = {"decode": t_decode, "processing": t_proc}
    return seq
