"""``samples depth`` and ``samples unregistered``: camera-based sample data (extension of ``samples``).

    ./run samples depth --poses 60 --resolution 320x240 --seed 0 --out DIR
    ./run samples unregistered --poses 10 --cameras 4 --out DIR

Both pose a MakeHuman subject with ``registered.posed_sequence`` (same ``--rig/--shape/--motion/...``
options as ``samples registered``) and hand the frames to :mod:`.depth_recording` or
:mod:`.unregistered`.  The noise seed is ``--seed`` unless ``--noise-seed`` is given.
"""
from __future__ import annotations

import dataclasses
import time

from ..solver.depth import camera
from ..solver.errors import ArticulaInputError
from .arguments import add_motion_arguments, add_subject_arguments, sequence_from_args
from .depth_noise import NOISELESS, NoiseParams

_HEAVY_GT = ("posed_vertices",)  # stored only on request (--save-vertices)


def parse_resolution(text: str) -> tuple:
    """``"320x240"`` -> (320, 240)."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ArticulaInputError(f"--resolution: expected WIDTHxHEIGHT such as 320x240, got {text!r}") from None
    if not (8 <= w <= 4096 and 6 <= h <= 4096):
        raise ArticulaInputError(f"--resolution: {w}x{h} is out of range (8x6 .. 4096x4096)")
    return w, h


def _noise(args) -> NoiseParams:
    kind = args.noise
    if kind == "auto":
        kind = "kinect_v1" if args.camera == "kinect_v1" else "mm"
    if kind == "none":
        return NOISELESS
    params = NoiseParams()
    if kind == "mm":
        params = dataclasses.replace(params, quantization="mm")
    if args.dropout is not None:
        params = dataclasses.replace(params, dropout=args.dropout)
    return params.validate()


def _add_common(p) -> None:
    add_subject_arguments(p)
    add_motion_arguments(p)
    p.add_argument("--camera", default="kinect_v1", type=camera.preset_key, choices=tuple(camera.PRESETS),
                   help=f"camera preset: {', '.join(camera.PRESETS)}")
    p.add_argument("--noise", default="auto", choices=("auto", "kinect_v1", "mm", "none"),
                   help="kinect_v1: Kinect v1 model with 1/8 px disparity steps; mm: the same noise with "
                   "millimetre rounding only (used for the other cameras by auto); none: exact depth")
    p.add_argument("--dropout", type=float, default=None, help="random missing-pixel rate (default 0.002)")
    p.add_argument("--noise-seed", type=int, default=None, help="seed of the sensor noise (default --seed)")
    p.add_argument("--out", required=True, help="output folder")


def _progress(label):
    def report(k, n):
        if k == n or k % 10 == 0:
            print(f"{label}: frame {k}/{n}", flush=True)
    return report


def _run_depth(args) -> int:
    from .depth_recording import CameraPlacement, generate_depth
    t0 = time.perf_counter()
    resolution, noise = parse_resolution(args.resolution), _noise(args)
    frames, faces, gt = sequence_from_args(args)
    keep = {k: v for k, v in gt.items() if k not in _HEAVY_GT}
    info = generate_depth(args.out, frames, faces, keep, resolution=resolution, camera=args.camera,
                          placement=CameraPlacement(args.distance, args.height, args.azimuth),
                          noise=noise, floor=not args.no_floor, background=args.background,
                          seed=args.seed if args.noise_seed is None else args.noise_seed,
                          save_clean=args.save_clean, save_vertices=args.save_vertices,
                          progress=_progress("samples depth"))
    intr = info["intrinsics"]
    print(f"samples depth: {info['frames']} depth PNGs {intr.width}x{intr.height} ({args.camera}) of a "
          f"{frames.shape[1]}-vertex subject -> {args.out} ({time.perf_counter() - t0:.2f} s, "
          f"rendering {info['seconds']:.2f} s)")
    return 0


def _run_unregistered(args) -> int:
    from .unregistered import ScanRig, generate_unregistered
    t0 = time.perf_counter()
    rig = ScanRig(n_cameras=args.cameras, camera=args.camera, resolution=parse_resolution(args.resolution),
                  outlier_fraction=args.outliers).validate()
    noise = _noise(args)
    frames, faces, gt = sequence_from_args(args)
    keep = {k: v for k, v in gt.items() if k not in _HEAVY_GT}
    info = generate_unregistered(args.out, frames, faces, keep, rig=rig, noise=noise,
                                 seed=args.seed if args.noise_seed is None else args.noise_seed,
                                 fmt=args.format, progress=_progress("samples unregistered"))
    counts = info["vertex_counts"]
    print(f"samples unregistered: {info['frames']} {args.format.upper()} scans from {args.cameras} cameras, "
          f"{min(counts)}..{max(counts)} vertices -> {args.out} ({time.perf_counter() - t0:.2f} s)")
    return 0


def add_sample_commands(sub) -> None:
    """Add ``depth`` and ``unregistered`` to the ``samples`` subcommands."""
    p = sub.add_parser("depth", help="depth recording: 16-bit mm PNGs + intrinsics.json + ground_truth.npz")
    _add_common(p)
    p.add_argument("--resolution", default="320x240", help="WIDTHxHEIGHT (default 320x240)")
    p.add_argument("--distance", type=float, default=2.8, help="camera distance from the subject (m)")
    p.add_argument("--height", type=float, default=1.0, help="camera height above the floor (m)")
    p.add_argument("--azimuth", type=float, default=0.0, help="camera direction (deg, 0 = in front)")
    p.add_argument("--no-floor", action="store_true", help="no floor plane")
    p.add_argument("--background", action="store_true", help="add a back wall 1.5 m behind the subject")
    p.add_argument("--save-clean", action="store_true", help="also store noise-free depth in ground_truth.npz")
    p.add_argument("--save-vertices", action="store_true", help="also store the posed vertices")
    p.set_defaults(func=_run_depth)
    p = sub.add_parser("unregistered", help="noisy partial multi-view scans (PLY/OBJ) + ground_truth.npz")
    _add_common(p)
    p.add_argument("--cameras", type=int, default=4, help="virtual cameras per frame (default 4)")
    p.add_argument("--resolution", default="320x240", help="largest camera grid WIDTHxHEIGHT (default 320x240)")
    p.add_argument("--outliers", type=float, default=0.002, help="outlier triangles per scan vertex")
    p.add_argument("--format", default="ply", choices=("ply", "obj"), help="scan file format")
    p.set_defaults(func=_run_unregistered)
