"""Synthetic depth recordings with exact ground truth: a posed mesh sequence seen by one static
depth camera, written as 16-bit millimetre PNGs plus ``intrinsics.json`` and ``ground_truth.npz``.

Scene: the subject (world metres, Z up, facing -Y as MakeHuman bodies do), optionally a floor
grid at the subject's lowest point and a back wall behind it.  The camera sits at ``distance`` from
the subject's centre in the horizontal direction ``azimuth_deg`` (0 = in front, i.e. on -Y; 90 = on
+X), ``height`` metres above the floor (the subject's lowest point), looking at the subject's centre.  Conventions of ``solver.depth.camera``.

Output folder::

    depth_0000.png ...   16-bit grayscale, millimetres, 0 = no measurement
    intrinsics.json      "articula-intrinsics/1" with the static camera's ``cam_to_world``
    ground_truth.npz     "articula-depth-gt/1", keys below

``ground_truth.npz`` keys: ``format``; ``intrinsics`` (6,) width, height, fx, fy, cx, cy;
``cam_to_world`` (N, 4, 4) camera (OpenCV axes) to world; ``blender_camera_matrix`` (N, 4, 4) the same
camera as a Blender camera's ``matrix_world`` (looks down -Z, +Y up); ``visible_ids`` (M,) int32 and
``visible_offsets`` (N+1,) int64: subject vertices of faces seen in frame k are
``visible_ids[visible_offsets[k]:visible_offsets[k+1]]``; ``faces`` (F, 3) int32; ``noise_seed``;
``noise_params`` (JSON str); optionally ``clean_depth_mm`` (N, H, W) uint16 (noise-free) and
``vertices`` (N, V, 3) float32; and every array of the caller's ground truth ``gt`` under its own
key (e.g. ``posed_heads``, ``pose_rotations`` of ``registered.posed_sequence``; keys listed above
take precedence).
"""
from __future__ import annotations

import dataclasses
import json
import os
import time

import numpy as np

from ..solver.depth import camera as cam
from ..solver.errors import ArticulaInputError
from ..solver.formats.png16 import write_png16
from .depth_noise import NoiseParams, apply_noise
from .depth_render import incidence_cosine, render_depth, visible_vertices

GT_FORMAT = "articula-depth-gt/1"


@dataclasses.dataclass(frozen=True)
class CameraPlacement:
    """Where the static camera stands relative to the subject (metres, degrees)."""

    distance: float = 2.8
    height: float = 1.0
    azimuth_deg: float = 0.0

    def cam_to_world(self, centre, floor_z: float = 0.0) -> np.ndarray:
        """(4, 4) camera-to-world for a subject centred at ``centre`` (3,) standing on ``floor_z``."""
        if not self.distance > 0.3:
            raise ArticulaInputError(f"camera distance must be > 0.3 m, got {self.distance}")
        a = np.radians(self.azimuth_deg)
        eye = np.array([centre[0] + self.distance * np.sin(a), centre[1] - self.distance * np.cos(a),
                        floor_z + self.height])
        return cam.look_at(eye, centre)


def grid_mesh(origin, e1, e2, n1: int, n2: int):
    """A planar grid of n1 x n2 quads (2 triangles each) spanning origin + [0,1] e1 + [0,1] e2.

    Large flat scenery is split into cells so that only the cells behind the camera are culled."""
    s1, s2 = np.linspace(0, 1, n1 + 1), np.linspace(0, 1, n2 + 1)
    a, b = np.meshgrid(s1, s2, indexing="ij")
    verts = np.asarray(origin, float) + a.reshape(-1, 1) * np.asarray(e1, float) + b.reshape(-1, 1) * np.asarray(e2, float)
    i = (np.arange(n1)[:, None] * (n2 + 1) + np.arange(n2)[None, :]).ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n2 + 1], 1), np.stack([i + 1, i + n2 + 2, i + n2 + 1], 1)])
    return verts, faces.astype(np.int64)


def scenery(centre, floor_z: float, floor: bool = True, wall: bool = False, wall_distance: float = 1.5,
            azimuth_deg: float = 0.0):
    """Floor (8 m x 8 m at ``floor_z``) and/or back wall (6 m x 3 m, ``wall_distance`` behind the
    subject, facing the camera) as one mesh ``(vertices, faces)``, 0.5 m cells."""
    parts = []
    if floor:
        parts.append(grid_mesh([centre[0] - 4, centre[1] - 4, floor_z], [8, 0, 0], [0, 8, 0], 16, 16))
    if wall:
        a = np.radians(azimuth_deg)
        back = np.array([-np.sin(a), np.cos(a), 0.0])          # away from the camera
        side = np.array([np.cos(a), np.sin(a), 0.0])
        base = np.array([centre[0], centre[1], floor_z]) + wall_distance * back - 3 * side
        parts.append(grid_mesh(base, 6 * side, [0, 0, 3.0], 12, 6))
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.concatenate(verts), np.concatenate(faces)


def render_frame(vertices, faces, scene_v, scene_f, cam_to_world, intr, noise: NoiseParams, rng):
    """One frame: world meshes -> (noisy depth m, clean depth m, visible subject vertex ids)."""
    all_v = cam.world_to_camera(np.concatenate([vertices, scene_v]), cam_to_world)
    all_f = np.concatenate([faces, scene_f + len(vertices)])
    clean, tri = render_depth(all_v, all_f, intr)
    noisy = apply_noise(clean, incidence_cosine(all_v, all_f, tri, intr), rng, noise, intr.fx)
    return noisy, clean, visible_vertices(tri, all_f, n_faces=len(faces))


def to_millimetres(depth_m: np.ndarray) -> np.ndarray:
    """Metres -> uint16 millimetres (rounded; 0 stays 0; beyond 65.535 m becomes 0 = missing)."""
    mm = np.rint(np.asarray(depth_m) * 1000.0)
    return np.where((mm > 0) & (mm <= 65535), mm, 0).astype(np.uint16)


def check_frames(frames, faces):
    """Validate a mesh sequence: (N, V, 3) finite float frames and (F, 3) int64 faces."""
    frames = np.asarray(frames, dtype=float)
    faces = np.asarray(faces)
    if frames.ndim != 3 or frames.shape[2] != 3 or len(frames) == 0:
        raise ArticulaInputError(f"frames must be (N, V, 3) with N >= 1, got {frames.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= frames.shape[1]:
        raise ArticulaInputError(f"faces must be (F, 3) indices into {frames.shape[1]} vertices")
    if not np.isfinite(frames).all():
        raise ArticulaInputError("frames contain NaN or infinite coordinates")
    return frames, faces.astype(np.int64)


def generate_depth(out_dir, frames, faces, gt: dict | None = None, resolution=(320, 240),
                   camera: str = "kinect_v1", placement: CameraPlacement = CameraPlacement(),
                   noise: NoiseParams = NoiseParams(), floor: bool = True, background: bool = False,
                   seed: int = 0, save_clean: bool = False, save_vertices: bool = False,
                   progress=None) -> dict:
    """Render ``frames`` (N, V, 3) world metres (faces (F, 3)) as a depth recording in ``out_dir``.

    ``resolution``: (width, height) of the camera preset ``camera`` rescaled.  Randomness: frame k
    uses ``numpy.random.default_rng([seed, k])`` only, so any frame can be regenerated alone.
    ``progress(k, N)`` is called after each frame.  Returns a summary dict (paths, timings).
    """
    frames, faces = check_frames(frames, faces)
    noise.validate()
    intr = cam.preset(camera, tuple(int(x) for x in resolution))
    os.makedirs(out_dir, exist_ok=True)
    lo, hi = frames.reshape(-1, 3).min(0), frames.reshape(-1, 3).max(0)
    centre = (lo + hi) / 2
    scene_v, scene_f = scenery(centre, lo[2], floor, background, azimuth_deg=placement.azimuth_deg)
    c2w = placement.cam_to_world(centre, lo[2])
    vis, clean_all, t0 = [], [], time.perf_counter()
    for k, verts in enumerate(frames):
        noisy, clean, seen = render_frame(verts, faces, scene_v, scene_f, c2w, intr, noise,
                                          np.random.default_rng([seed, k]))
        write_png16(os.path.join(out_dir, f"depth_{k:04d}.png"), to_millimetres(noisy))
        vis.append(seen.astype(np.int32))
        if save_clean:
            clean_all.append(to_millimetres(clean))
        if progress:
            progress(k + 1, len(frames))
    cam.save_intrinsics(os.path.join(out_dir, "intrinsics.json"), intr, cam_to_world=c2w)
    gt_arrays = _ground_truth(frames, faces, gt, intr, c2w, vis, noise, seed, clean_all, save_vertices)
    gt_path = os.path.join(out_dir, "ground_truth.npz")
    np.savez_compressed(gt_path + ".part.npz", **gt_arrays)
    os.replace(gt_path + ".part.npz", gt_path)
    return {"out_dir": out_dir, "frames": len(frames), "intrinsics": intr, "seconds": time.perf_counter() - t0,
            "ground_truth": gt_path}


def _ground_truth(frames, faces, gt, intr, c2w, vis, noise, seed, clean_all, save_vertices):
    n = len(frames)
    c2w_all = np.repeat(c2w[None], n, axis=0)
    out = {
        "format": np.array(GT_FORMAT),
        "intrinsics": np.array([intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy]),
        "cam_to_world": c2w_all,
        "blender_camera_matrix": np.stack([cam.blender_from_cv(m) for m in c2w_all]),
        "visible_ids": np.concatenate(vis) if vis else np.zeros(0, np.int32),
        "visible_offsets": np.r_[0, np.cumsum([len(v) for v in vis])].astype(np.int64),
        "faces": faces.astype(np.int32),
        "noise_seed": np.array(seed),
        "noise_params": np.array(json.dumps(dataclasses.asdict(noise))),
    }
    if clean_all:
        out["clean_depth_mm"] = np.stack(clean_all)
    if save_vertices:
        out["vertices"] = frames.astype(np.float32)
    for key, value in (gt or {}).items():
        arr = np.asarray(value)
        if key not in out and arr.dtype != object:
            out[key] = arr
    return out


def ragged(ids: np.ndarray, offsets: np.ndarray, k: int) -> np.ndarray:
    """Frame ``k`` of a ragged array stored as concatenated ``ids`` + ``offsets`` (N+1,)."""
    return ids[offsets[k]:offsets[k + 1]]
