"""Unregistered scan sequences: the poses of a registered sequence as noisy, partial,
re-triangulated surfaces, as a multi-view depth scanner would deliver them.

Per frame, ``n_cameras`` virtual depth cameras stand around the subject (evenly spaced azimuths
with a random common offset and per-camera jitter in azimuth, distance and height).  Each camera
renders the subject (``depth_render``), gets the depth-camera noise model (``depth_noise``), and
its depth grid is turned into a mesh: neighbouring valid pixels form two triangles per 2x2 pixel
cell, and triangles spanning a depth jump (``max_jump_m + max_jump_rel * z``) are dropped.  Each
camera's grid resolution is drawn at random (``resolution_scale``), so vertex counts and
topology differ between frames.  The cameras' meshes are merged (concatenated, not fused) in world
coordinates, unused vertices removed, and a few outliers (tiny floating triangles around the body)
added.  Everything is deterministic from ``seed`` (frame k uses ``default_rng([seed, k])``).

Output folder: ``scan_0000.ply`` (or ``.obj``) per frame, metres, triangles facing the camera that saw
them, written in the format's axis convention (``mesh_files``: PLY world Z up as is, OBJ Y up as
Blender's exporter writes it); ``ground_truth.npz`` ("articula-unregistered-gt/1", world Z up):

=========================  =====================================================================
vertex_counts (N,)         vertices per scan;  face_counts (N,)
source_face, offsets       (sum V,) int32 subject triangle each scan vertex was measured on (-1 =
                           outlier), frame k = ``source_face[source_offsets[k]:source_offsets[k+1]]``
source_camera              (sum V,) int8 the camera (index into cam_to_world[k]) that saw it (-1 = outlier)
cam_to_world (N,C,4,4)     every virtual camera (OpenCV axes); intrinsics (N,C,6): w, h, fx, fy, cx, cy
faces (F,3)                the subject's triangles (``source_face`` indexes them)
noise_params, seed         JSON str, int
file_axes (2,)             (forward, up) of the scan files (``solver.formats.axes``): ("Y", "Z") PLY,
                           ("NEGATIVE_Z", "Y") OBJ; file = ``world_to_file(world, ext)``
(caller's gt)              e.g. ``posed_heads``, ``pose_rotations`` of ``registered.posed_sequence``
=========================  =====================================================================
"""
from __future__ import annotations

import dataclasses
import json
import os

import numpy as np

from ..solver.depth import camera as cam
from ..solver.errors import ArticulaInputError
from ..solver.formats.axes import format_axes
from .depth_noise import NoiseParams, apply_noise
from .depth_recording import check_frames
from .depth_render import incidence_cosine, render_depth
from .mesh_files import FORMATS, SequenceWriter

GT_FORMAT = "articula-unregistered-gt/1"


@dataclasses.dataclass(frozen=True)
class ScanRig:
    """Virtual multi-view scanner (metres, degrees, pixels)."""

    n_cameras: int = 4
    camera: str = "kinect_v1"
    resolution: tuple = (320, 240)       # largest grid; each camera draws a scale in resolution_scale
    resolution_scale: tuple = (0.6, 1.0)
    distance: tuple = (2.2, 2.8)
    height: tuple = (0.8, 1.6)
    azimuth_jitter_deg: float = 12.0
    max_jump_m: float = 0.02             # triangle dropped if its depth range exceeds this + rel * z
    max_jump_rel: float = 0.02
    outlier_fraction: float = 0.002      # outlier triangles per scan vertex
    outlier_margin_m: float = 0.25

    def validate(self) -> "ScanRig":
        if not 1 <= self.n_cameras <= 16:
            raise ArticulaInputError(f"n_cameras must be 1..16, got {self.n_cameras}")
        lo, hi = self.resolution_scale
        if not 0.1 <= lo <= hi <= 1.0:
            raise ArticulaInputError(f"resolution_scale must satisfy 0.1 <= lo <= hi <= 1, got {self.resolution_scale}")
        if not 0 < self.distance[0] <= self.distance[1]:
            raise ArticulaInputError(f"distance range {self.distance} is invalid")
        if not 0 <= self.outlier_fraction < 0.5:
            raise ArticulaInputError(f"outlier_fraction must be in [0, 0.5), got {self.outlier_fraction}")
        cam.preset(self.camera)
        return self


def grid_triangles(depth_m: np.ndarray, max_jump_m: float, max_jump_rel: float) -> np.ndarray:
    """Triangulate a depth grid: (T, 3) flat pixel indices, two triangles per 2x2 cell of valid
    pixels, wound so the normals face the camera, without triangles across depth jumps."""
    h, w = depth_m.shape
    idx = np.arange(h * w).reshape(h, w)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    z = depth_m.ravel()
    tris = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    zt = z[tris]
    zmin = zt.min(axis=1)
    ok = (zmin > 0) & (zt.max(axis=1) - zmin <= max_jump_m + max_jump_rel * zmin)
    return tris[ok]


def depth_mesh(depth_m, intr, cam_to_world, max_jump_m=0.02, max_jump_rel=0.02):
    """A depth image as a world-space mesh: (vertices (K, 3), faces (T, 3), pixel ids (K,))."""
    tris = grid_triangles(depth_m, max_jump_m, max_jump_rel)
    used, faces = np.unique(tris, return_inverse=True)
    pts, _ = cam.depth_to_points(depth_m, intr)  # row-major valid pixels
    valid_idx = np.flatnonzero(depth_m.ravel() > 0)
    pos = np.searchsorted(valid_idx, used)
    world = cam.camera_to_world(pts[pos], cam_to_world)
    return world, faces.reshape(-1, 3).astype(np.int64), used


def _cameras(rng, centre, rig: ScanRig):
    base = rng.uniform(0, 360) + 360.0 * np.arange(rig.n_cameras) / rig.n_cameras
    az = np.radians(base + rng.uniform(-rig.azimuth_jitter_deg, rig.azimuth_jitter_deg, rig.n_cameras))
    dist = rng.uniform(*rig.distance, rig.n_cameras)
    height = rng.uniform(*rig.height, rig.n_cameras)
    scale = rng.uniform(*rig.resolution_scale, rig.n_cameras)
    out = []
    for a, r, hgt, s in zip(az, dist, height, scale):
        eye = np.array([centre[0] + r * np.sin(a), centre[1] - r * np.cos(a), hgt])
        res = (max(8, int(round(rig.resolution[0] * s))), max(6, int(round(rig.resolution[1] * s))))
        out.append((cam.look_at(eye, centre), cam.preset(rig.camera, res)))
    return out


def _outliers(rng, lo, hi, n, margin):
    """n tiny floating triangles (1 cm) in the box [lo - margin, hi + margin]."""
    centres = rng.uniform(lo - margin, hi + margin, (n, 3))
    verts = (centres[:, None, :] + rng.normal(scale=0.005, size=(n, 3, 3))).reshape(-1, 3)
    return verts, np.arange(3 * n).reshape(n, 3)


def scan_frame(vertices, faces, rng, rig: ScanRig = ScanRig(), noise: NoiseParams = NoiseParams()):
    """One unregistered scan of the posed mesh ``vertices`` (V, 3) world metres, ``faces`` (F, 3).

    Returns ``(scan_vertices (K, 3), scan_faces (T, 3), source_face (K,), source_camera (K,),
    cameras)``: the subject triangle each vertex lies on and the camera that saw it (-1 for
    outliers), and the cameras as a list of ``(cam_to_world (4, 4), Intrinsics)``."""
    lo, hi = vertices.min(0), vertices.max(0)
    cameras = _cameras(rng, (lo + hi) / 2, rig)
    parts_v, parts_f, parts_src, parts_cam, offset = [], [], [], [], 0
    for index, (c2w, intr) in enumerate(cameras):
        vc = cam.world_to_camera(vertices, c2w)
        clean, tri = render_depth(vc, faces, intr)
        noisy = apply_noise(clean, incidence_cosine(vc, faces, tri, intr), rng, noise, intr.fx)
        v, f, pix = depth_mesh(noisy, intr, c2w, rig.max_jump_m, rig.max_jump_rel)
        parts_v.append(v)
        parts_f.append(f + offset)
        parts_src.append(tri.ravel()[pix])   # lateral noise may move a pixel's depth to a
        parts_cam.append(np.full(len(v), index))  # neighbour's surface: the source is that pixel's face
        offset += len(v)
    n_out = int(round(rig.outlier_fraction * offset))
    ov, of = _outliers(rng, lo, hi, n_out, rig.outlier_margin_m)
    parts_v.append(ov)
    parts_f.append(of + offset)
    parts_src.append(np.full(len(ov), -1))
    parts_cam.append(np.full(len(ov), -1))
    return (np.concatenate(parts_v), np.concatenate(parts_f), np.concatenate(parts_src).astype(np.int32),
            np.concatenate(parts_cam).astype(np.int8), cameras)


def generate_unregistered(out_dir, frames, faces, gt: dict | None = None, rig: ScanRig = ScanRig(),
                          noise: NoiseParams = NoiseParams(), seed: int = 0, fmt: str = "ply",
                          progress=None) -> dict:
    """Write one scan per frame of ``frames`` (N, V, 3) to ``out_dir`` (module docstring).

    Returns a summary dict (vertex counts, paths)."""
    frames, faces = check_frames(frames, faces)
    rig.validate()
    noise.validate()
    if fmt not in FORMATS:
        raise ArticulaInputError(f"format: unknown mesh format {fmt!r} (choose from {', '.join(FORMATS)})")
    os.makedirs(out_dir, exist_ok=True)
    counts, fcounts, sources, seen_by, c2ws, intrs = [], [], [], [], [], []
    for k, verts in enumerate(frames):
        sv, sf, src, src_cam, cams = scan_frame(verts, faces, np.random.default_rng([seed, k]), rig, noise)
        SequenceWriter(sf, fmt, from_world=True).write(os.path.join(out_dir, f"scan_{k:04d}.{fmt}"), sv)
        counts.append(len(sv))
        fcounts.append(len(sf))
        sources.append(src)
        seen_by.append(src_cam)
        c2ws.append(np.stack([c for c, _ in cams]))
        intrs.append(np.array([[i.width, i.height, i.fx, i.fy, i.cx, i.cy] for _, i in cams]))
        if progress:
            progress(k + 1, len(frames))
    out = {"format": np.array(GT_FORMAT), "vertex_counts": np.array(counts), "face_counts": np.array(fcounts),
           "source_face": np.concatenate(sources), "source_camera": np.concatenate(seen_by),
           "source_offsets": np.r_[0, np.cumsum(counts)].astype(np.int64),
           "cam_to_world": np.stack(c2ws), "intrinsics": np.stack(intrs), "faces": faces.astype(np.int32),
           "seed": np.array(seed), "noise_params": np.array(json.dumps(dataclasses.asdict(noise))),
           "scan_rig": np.array(json.dumps(dataclasses.asdict(rig))),
           "file_axes": np.array(format_axes("." + fmt))}
    for key, value in (gt or {}).items():
        arr = np.asarray(value)
        if key not in out and arr.dtype != object:
            out[key] = arr
    path = os.path.join(out_dir, "ground_truth.npz")
    np.savez_compressed(path + ".part.npz", **out)
    os.replace(path + ".part.npz", path)
    return {"out_dir": out_dir, "frames": len(frames), "vertex_counts": counts, "ground_truth": path}
