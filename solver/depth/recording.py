"""Importing a depth recording or a point-cloud sequence: which files are frames, decoding the depth
PNGs (in batches), processing every frame (:mod:`solver.depth.frames`) on worker threads with one floor
and one background for the whole recording -> a :class:`~solver.formats.point_files.PointSequence`.

The preprocessing is the depth-camera tracking dissertation's (ch. 4: near/far depth thresholds cut out
the subject; ch. 5: the ground plane is fitted and the points within 20 mm of it removed, the static
background subtracted); docs/import_depth.md lists the steps and options.
"""
from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from . import camera as cam
from . import frames as dp
from .. import parallel
from ..errors import ArticulaInputError
from ..formats.png16 import read_png16, read_png16_many, read_png_header
from ..formats.point_files import PointSequence, check_point_file, read_point_file
from ..formats.scan_files import natural_sorted

DEPTH_EXTENSIONS = (".png", ".exr")
COLOR_EXTENSIONS = (".png", ".jpg", ".jpeg")
_CHUNK = 8          # consecutive depth frames decoded and processed together by one worker thread
_FLOOR_FRAMES = 8   # the floor is fitted on points pooled from this many frames spread over the recording
_FLOOR_SAMPLE = 5000  # points drawn from each of them


# ----------------------------------------------------------------------------------------- files

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
    return [os.path.join(directory, n) for n in natural_sorted(frames)]


def camera_file(path: str) -> tuple:
    """``(Intrinsics, cam_to_world (4, 4) or None)`` of an ``intrinsics.json`` (validated): the one reader of
    a recording's camera file, for the importer and the depth tracker."""
    return cam.load_intrinsics(path), cam.load_camera_pose(path)


def unit_options(options: dp.DepthOptions, intr, depth_scale: float | None = None) -> dp.DepthOptions:
    """``options`` with ``depth_scale`` (metres per 16-bit PNG unit) = ``depth_scale`` when the user gave
    one, else the camera's ``depth_unit_m`` (``intrinsics.json``; 0.001 for the presets)."""
    scale = intr.depth_unit_m if depth_scale is None else depth_scale
    return dataclasses.replace(options, depth_scale=float(scale))


def _require_16bit(raw: np.ndarray, path: str) -> np.ndarray:
    if raw.dtype != np.uint16:
        raise ArticulaInputError(f"{path}: 8-bit PNG; depth frames must be 16-bit grayscale "
                                 "(an 8-bit image cannot hold millimetre depths)")
    return raw


def read_depth_png(path: str) -> np.ndarray:
    """A 16-bit grayscale depth PNG -> (H, W) uint16 raw values; 8-bit files are refused."""
    return _require_16bit(read_png16(path), path)


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


def depth_frames(paths, read_exr=None) -> list[DepthFrame]:
    """The frames of ``paths``: 16-bit PNGs (decoded in batches) and EXRs in metres, read one at a time
    when needed by ``read_exr(path) -> (H, W)`` (Blender's image reader); EXR without it is refused."""
    exr = [p for p in paths if p.lower().endswith(".exr")]
    if exr and read_exr is None:
        raise ArticulaInputError(f"{exr[0]}: EXR depth frames are read by Blender's image loader; use the "
                                 "batch command or the add-on, or 16-bit PNG frames")
    return [DepthFrame(p, (lambda p=p: read_exr(p)), metres=True) if p in exr else png_frames([p])[0]
            for p in paths]


def check_png_frames(frames) -> None:
    """Every PNG frame's header (first 33 bytes: a PNG, 16-bit, the size of the first PNG frame, a
    file size that fits its image) checked before any frame is decoded."""
    first = None
    for f in frames:
        if f is None or f.png is None:
            continue
        width, height, depth, _ = read_png_header(f.png)
        if depth != 16:
            _require_16bit(np.zeros(0, np.uint8), f.png)
        if first is None:
            first = (f.png, width, height)
        elif (width, height) != first[1:]:
            raise ArticulaInputError(f"{f.name}: {width}x{height} pixels, but {os.path.basename(first[0])} is "
                                     f"{first[1]}x{first[2]}; all frames must have the same size")


class _Prefetch:
    """Raw frames decoded ahead in the calling thread: when frames are read in order, the next
    consecutive PNG frames are decoded together (``png16.read_png16_many`` unfilters a batch of
    equal-size frames in one pass, faster on Paeth/Average-filtered files) and kept until asked for."""

    def __init__(self, frames, batch: int = 8, start: int = -1):
        self.frames, self.batch, self.ready, self.last = frames, batch, {}, start - 1

    def raw(self, k: int) -> np.ndarray:
        sequential, self.last = k == self.last + 1, k
        if k in self.ready:
            return self.ready.pop(k)
        f = self.frames[k]
        if f.png is None:
            return f.load()
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
                    _require_16bit(a, self.frames[j].png)
                break  # reported when its turn comes
            self.ready[j] = a
        return self.ready.pop(k)


def _no_progress(fraction, text=""):
    pass


def _frame_metres(frame: DepthFrame, opts: dp.DepthOptions, shape, first_name, raw=None) -> np.ndarray:
    """(H, W) float32 depth of one frame in metres, NaN where out of range (``frames.depth_in_metres``);
    every frame must have the first frame's ``shape``."""
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


class _SetupFrames:
    """Depth frames in metres for the set-up steps (background, floor), which read frames out of order:
    each decoded once and kept; ``seconds`` sums the decoding time."""

    def __init__(self, frames: list, opts: dp.DepthOptions):
        t = time.perf_counter()
        self.frames, self.opts, self.decoded = frames, opts, {}
        self.prefetch = _Prefetch(frames)
        first = self.prefetch.raw(0)
        self.prefetch.ready[0] = first
        self.shape = tuple(first.shape[:2])
        self.seconds = time.perf_counter() - t

    def metres(self, k: int) -> np.ndarray:
        if k not in self.decoded:
            t = time.perf_counter()
            self.decoded[k] = _frame_metres(self.frames[k], self.opts, self.shape, self.frames[0].name,
                                            self.prefetch.raw(k))
            self.seconds += time.perf_counter() - t
        return self.decoded[k]


# ------------------------------------------------------------------------------ recording-wide steps

def _fit_floor(points_of, n: int, opts: dp.DepthOptions):
    """One floor plane for the recording: RANSAC + least squares (``frames.ransac_plane``) on up to
    5000 points from each of up to 8 frames spread over it; ``points_of(k)`` gives frame k's candidate
    points (K, 3).  Returns ``(plane (n, d) or None, inlier mask of the pooled points)``."""
    rng = np.random.default_rng(opts.seed)
    pool = []
    for k in _pick(n, _FLOOR_FRAMES):
        pts = points_of(k)
        if len(pts) > _FLOOR_SAMPLE:
            pts = pts[rng.choice(len(pts), _FLOOR_SAMPLE, replace=False)]
        pool.append(pts)
    pool = np.concatenate(pool) if pool else np.zeros((0, 3), np.float32)
    plane, inl = dp.ransac_plane(pool, opts.floor_tolerance, opts.floor_iterations, opts.seed,
                                 max_tilt_deg=opts.floor_max_tilt)
    if plane is not None and inl.sum() >= max(50, opts.floor_min_fraction * len(pool)):
        return plane, inl
    return None, inl


def _matching_intrinsics(intr, shape, first_name: str, notes: list):
    """``intr`` for frames of ``shape`` (H, W): rescaled (noted) when only the resolution differs."""
    if (intr.height, intr.width) == shape:
        return intr
    if abs(shape[1] / shape[0] - intr.width / intr.height) > 1e-6:
        raise ArticulaInputError(f"{first_name}: {shape[1]}x{shape[0]} pixels, but the intrinsics "
                                 f"{intr.name!r} are for {intr.width}x{intr.height}")
    notes.append(f"intrinsics rescaled to the frames' {shape[1]}x{shape[0]} pixels")
    return intr.with_resolution(shape[1], shape[0])


def _background(src: _SetupFrames, background, opts: dp.DepthOptions, notes: list):
    """(H, W) metres of the empty scene: the given frame, else the per-pixel median of
    ``opts.background_frames`` frames spread over the recording (right wherever the subject covers a
    pixel in fewer than half of them, i.e. when it moves)."""
    if background is not None:
        return _frame_metres(background, opts, src.shape, src.frames[0].name)
    picked = _pick(len(src.frames), opts.background_frames)
    notes.append(f"background = per-pixel median of {len(picked)} frames spread over the recording")
    return dp.median_background([src.metres(k) for k in picked])


def _depth_floor(src: _SetupFrames, rays, opts: dp.DepthOptions, notes: list):
    """The floor from the range-clipped points (before background removal: the floor is static)."""
    def candidates(k):
        z = src.metres(k)
        grid = dp.backproject_grid(z, rays)
        return grid[dp.frame_mask(z, grid, opts)]

    plane, inl = _fit_floor(candidates, len(src.frames), opts)
    if plane is not None:
        notes.append(f"floor found {plane[1]:.3f} m below the camera "
                     f"({100 * inl.mean():.0f}% of the sampled points)")
    else:
        notes.append("no floor found (no plane within "
                     f"{opts.floor_max_tilt:g} deg of level holding {100 * opts.floor_min_fraction:g}% of the points)")
    return plane


def _process_frames(src: _SetupFrames, colors, rays, bg, floor, progress):
    """Every frame decoded and processed, in chunks of 8 consecutive frames on ``opts.workers`` threads
    (0 = up to 4; numpy and zlib release the GIL), kept in order.  Returns ``(FramePoints list,
    decode seconds, processing seconds (both summed over the threads), threads used)``."""
    frames, opts, n = src.frames, src.opts, len(src.frames)

    def run_chunk(ks):
        """Decode and process consecutive frames ks (in a worker thread; no shared state written)."""
        pref = _Prefetch(frames, start=ks[0])
        done, t_dec, t_pro, measured = [], 0.0, 0.0, []
        for k in ks:
            t = time.perf_counter()
            raw = None if k in src.decoded else pref.raw(k)
            z = src.decoded[k] if raw is None else _frame_metres(frames[k], opts, src.shape, frames[0].name, raw)
            if not np.isfinite(z).any():      # nothing in range: keep the frame's measured depths
                measured.append(_measured_depths(frames[k], opts, raw))
            col = colors[k]() if colors is not None else None
            t1 = time.perf_counter()
            done.append(dp.process_depth(z, rays, opts, bg, floor, col))
            t_dec, t_pro = t_dec + t1 - t, t_pro + time.perf_counter() - t1
        return done, t_dec, t_pro, measured

    chunks = [list(range(i, min(i + _CHUNK, n))) for i in range(0, n, _CHUNK)]
    workers = opts.workers or min(4, os.cpu_count() or 1)

    def report(i, result):
        last = chunks[i][-1] + 1
        progress(0.05 + 0.95 * last / n, f"frame {last}/{n}")

    results = parallel.map_in_order(run_chunk, chunks, workers, report)
    empty = [m for r in results for m in r[3]]
    if len(empty) == n:
        _refuse_out_of_range(frames[0].name, n, opts, empty, opts.depth_scale)
    out = [fp for done, *_ in results for fp in done]
    return out, sum(r[1] for r in results), sum(r[2] for r in results), min(workers, len(chunks))


def _measured_depths(frame: DepthFrame, opts: dp.DepthOptions, raw=None):
    """(nearest, farthest) measured depth of a frame in metres (its non-zero finite pixels), or None."""
    raw = frame.load() if raw is None else raw
    z = np.asarray(raw, np.float64) * (1.0 if frame.metres else opts.depth_scale)
    z = z[np.isfinite(z) & (z > 0)]
    return (float(z.min()), float(z.max())) if z.size else None


def _refuse_out_of_range(first: str, n: int, opts: dp.DepthOptions, measured: list, scale=None) -> None:
    """Every frame lies outside the depth range: say which range, and what the frames measure
    (``measured``: (nearest, farthest) metres or None per frame; ``scale``: the PNG depth scale)."""
    where = os.path.dirname(first) or first
    ranges = [m for m in measured if m is not None]
    if not ranges:
        raise ArticulaInputError(f"{where}: all {n} frames are empty (no depth measured)")
    lo, hi = min(m[0] for m in ranges), max(m[1] for m in ranges)
    at = f" at a depth scale of {scale:g} m per unit" if scale is not None else ""
    fix = " or the depth scale (--depth-scale)" if scale is not None else ""
    raise ArticulaInputError(
        f"{where}: no point of the {n} frames lies in the depth range {opts.depth_min:g}-{opts.depth_max:g} m; "
        f"the frames measure {lo:.3g}-{hi:.3g} m{at}: set the depth range (Depth Min/Max, "
        f"--depth-min/--depth-max){fix}")


@dataclasses.dataclass
class RecordingSetup:
    """What every frame of a depth recording shares: the (rescaled) intrinsics ``intr``, the pixel
    ``rays``, the static ``background`` (H, W) metres or None, the ``floor`` plane (n, d) in the sensor
    frame or None, the frame ``shape`` (H, W), ``notes`` for the user, and ``src`` (the decoded set-up
    frames, kept for the importer)."""
    intr: object
    rays: tuple
    background: np.ndarray | None
    floor: tuple | None
    shape: tuple
    notes: list
    src: object


def recording_setup(frames: list, intr, opts: dp.DepthOptions, background: DepthFrame | None = None,
                    progress=_no_progress) -> RecordingSetup:
    """Background (given frame or median) and floor of a recording, from a few frames spread over it
    (the dissertation's ch. 5 preprocessing: ground plane fitted once, static background subtracted)."""
    src = _SetupFrames(frames, opts)
    notes = []
    intr = _matching_intrinsics(intr, src.shape, frames[0].name, notes)
    rays = dp.pixel_rays(intr)
    bg = floor = None
    if opts.subtract_background:
        progress(0.0, "background")
        bg = _background(src, background, opts, notes)
    if opts.remove_floor:
        progress(0.02, "floor")
        floor = _depth_floor(src, rays, opts, notes)
    return RecordingSetup(intr, rays, bg, floor, src.shape, notes, src)


def stream_metres(frames: list, opts: dp.DepthOptions, shape):
    """``(k, depth (H, W) float32 metres, NaN invalid)`` for every frame in order, decoding PNGs a few at
    a time (memory stays bounded for recordings of any length)."""
    prefetch = _Prefetch(frames)
    for k, frame in enumerate(frames):
        yield k, _frame_metres(frame, opts, shape, frames[0].name, prefetch.raw(k))


# ------------------------------------------------------------------------------------ importers

def import_depth(frames: list, intr, opts: dp.DepthOptions, progress=_no_progress,
                 background: DepthFrame | None = None, colors: list | None = None) -> PointSequence:
    """Depth frames -> :class:`PointSequence`.

    ``intr``: :class:`~.camera.Intrinsics`; when the frames have another size with the same aspect
    ratio the intrinsics are rescaled (noted in ``notes``), otherwise the import fails.
    ``background``: a frame of the empty scene for background subtraction; without one the per-pixel
    median of ``opts.background_frames`` frames spread over the recording is used.
    ``colors``: optional list (one per frame) of callables returning (H, W, 3) float images.
    The floor plane is fitted once (:func:`_fit_floor`) and points on or below it are removed from
    every frame.  ``timings``: wall seconds of set-up, frames and concatenation; decode and processing
    seconds summed over the worker threads.
    """
    opts.validate()
    if not frames:
        raise ArticulaInputError("no depth frames to import")
    intr.validate()
    if colors is not None and len(colors) != len(frames):
        raise ArticulaInputError(f"{len(colors)} colour frames for {len(frames)} depth frames; "
                                 "the counts must match")
    check_png_frames(list(frames) + [background])
    t0 = time.perf_counter()
    setup = recording_setup(frames, intr, opts, background, progress)
    src, intr, rays, bg, floor, notes = setup.src, setup.intr, setup.rays, setup.background, setup.floor, setup.notes
    t_frames = time.perf_counter()
    t_setup = t_frames - t0
    out, t_decode, t_proc, workers = _process_frames(src, colors, rays, bg, floor, progress)
    progress(1.0, "done")
    t = time.perf_counter()
    t_frames = t - t_frames
    seq = PointSequence.from_frames(out, world_from_sensor=dp.world_from_sensor(floor), floor=floor,
                                    intrinsics=(intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy),
                                    frame_names=[f.name for f in frames], notes=notes)
    seq.timings = {"setup": t_setup, "frames": t_frames, "concatenate": time.perf_counter() - t,
                   "decode": src.seconds + t_decode, "processing": t_proc, "workers": workers}
    return seq


def import_clouds(paths: list, opts: dp.DepthOptions, progress=_no_progress, intr=None) -> PointSequence:
    """Point-cloud files (sensor frame: x right, y down, z forward) -> :class:`PointSequence`.

    Range clip on z, floor removal (one plane, :func:`_fit_floor`), voxel downsampling and PCA normals
    as for depth frames; background subtraction needs depth images and is not applied (a note says so)."""
    opts.validate()
    if not paths:
        raise ArticulaInputError("no point-cloud frames to import")
    notes = []
    if opts.subtract_background:
        notes.append("background subtraction needs depth images; not applied to point clouds")
    timings = {"decode": 0.0, "processing": 0.0}
    cache = {}

    def read(k):
        if k not in cache:
            t = time.perf_counter()
            cache[k] = read_point_file(paths[k])
            timings["decode"] += time.perf_counter() - t
        return cache[k]

    def candidates(k):
        p = read(k)[0]
        return p[(p[:, 2] >= opts.depth_min) & (p[:, 2] <= opts.depth_max)]

    for path in paths:       # every file's header and size before the first is read
        check_point_file(path)
    floor = None
    if opts.remove_floor:
        floor, _ = _fit_floor(candidates, len(paths), opts)
        notes.append("no floor found" if floor is None else f"floor found {floor[1]:.3f} m below the sensor origin")
    out, measured = [], []
    for k in range(len(paths)):
        progress(k / len(paths), f"frame {k + 1}/{len(paths)}")
        pts, col = read(k)
        cache.pop(k, None)
        z = pts[:, 2]
        if not ((z >= opts.depth_min) & (z <= opts.depth_max)).any():
            measured.append((float(z.min()), float(z.max())) if len(z) else None)
        t = time.perf_counter()
        out.append(dp.process_cloud(pts, opts, floor, col))
        timings["processing"] += time.perf_counter() - t
    if len(measured) == len(paths):
        _refuse_out_of_range(paths[0], len(paths), opts, measured)
    if any(f.colors is None for f in out) and any(f.colors is not None for f in out):
        notes.append("some frames have no colours; colours dropped")
        for f in out:
            f.colors = None
    progress(1.0, "done")
    intr_t = None if intr is None else (intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy)
    seq = PointSequence.from_frames(out, world_from_sensor=dp.world_from_sensor(floor), floor=floor,
                                    intrinsics=intr_t, frame_names=list(paths), notes=notes)
    seq.timings = timings
    return seq
