"""Synthetic depth recordings for the depth-tracking benchmark: one MakeHuman subject turning on the spot
(:mod:`.turn`, hybrid skin) in front of a Kinect v1 (noise of :mod:`.depth_noise`) standing on a floor.

:func:`bench_recording` writes (or reuses) a folder of :mod:`.depth_recording`::

    depth_0000.png ...   16-bit millimetres;  intrinsics.json with the static camera's cam_to_world
    ground_truth.npz     the depth ground truth plus registered.posed_sequence's (posed_heads, poses,
                         hybrid weights, major_joint_labels/bones) and:
                         major_joints (N, 14, 3) world metres, bench_key (JSON of the parameters)
    model.npz            the subject's hybrid model ("articula-model/1", no poses)

World: metres, Z up, the floor at z = 0, the subject facing -Y towards the camera at the start.  The camera
looks horizontally at the centre of the body's bounding box over all frames from in front (-Y), at the
smallest distance of at least :data:`MIN_DISTANCE` that keeps every body vertex of every frame inside
the image with a :data:`MARGIN` border.
"""
from __future__ import annotations

import json
import os
import re
import time

import numpy as np

from ..solver.depth import camera as cam
from ..solver.formats.bundle import save_bundle
from ..solver.rig.model import Model, Skeleton
from .depth_noise import NoiseParams
from .depth_recording import CameraPlacement, generate_depth
from .registered import posed_sequence

#: Changes when the generator's output for the same parameters changes (invalidates cached folders).
BENCH_VERSION = 1
CAMERA = "kinect_v1"
MIN_DISTANCE, MAX_DISTANCE = 2.6, 4.0     # metres, camera to the body's centre (horizontal)
MARGIN = 0.02                             # border kept free, fraction of the image width
_HEAVY = ("posed_vertices", "bone_matrices", "lbs_weights")


def bench_key(subject_seed, resolution, frames, seed, rig, turn_degrees) -> str:
    """The parameters of a recording as a canonical JSON string (stored as ``bench_key``)."""
    return json.dumps({"version": BENCH_VERSION, "subject_seed": int(subject_seed), "resolution":
                       [int(x) for x in resolution], "frames": int(frames), "seed": int(seed), "rig": str(rig),
                       "turn_degrees": float(turn_degrees), "camera": CAMERA}, sort_keys=True)


def whole_body_placement(frames: np.ndarray, intr: cam.Intrinsics) -> CameraPlacement:
    """The camera in front of ``frames`` (N, V, 3) world metres, at the height of their bounding box's
    centre, nearest (5 cm steps from :data:`MIN_DISTANCE`) with every vertex inside the image."""
    pts = frames.reshape(-1, 3)
    lo, hi = pts.min(0), pts.max(0)
    centre = (lo + hi) / 2
    border = MARGIN * intr.width
    for distance in np.arange(MIN_DISTANCE, MAX_DISTANCE + 1e-9, 0.05):
        placement = CameraPlacement(float(round(distance, 2)), float(centre[2] - lo[2]))
        uv, z = cam.project(cam.world_to_camera(pts, placement.cam_to_world(centre, lo[2])), intr)
        if (z > 0).all() and (uv.min(0) >= border).all() and (uv[:, 0] <= intr.width - 1 - border).all() \
                and (uv[:, 1] <= intr.height - 1 - border).all():
            return placement
    return CameraPlacement(MAX_DISTANCE, float(centre[2] - lo[2]))


def _cached(out_dir, key, frames) -> bool:
    names = ["ground_truth.npz", "intrinsics.json", "model.npz"] + [f"depth_{k:04d}.png" for k in range(frames)]
    if not all(os.path.isfile(os.path.join(out_dir, n)) for n in names):
        return False
    try:
        with np.load(os.path.join(out_dir, "ground_truth.npz")) as g:
            return "bench_key" in g.files and str(g["bench_key"]) == key
    except (OSError, ValueError):
        return False


def _render(out_dir, key, subject_seed, resolution, frames, seed, rig, turn_degrees) -> None:
    posed, faces, gt = posed_sequence(rig, None, frames, "turn", "hybrid", seed, subject_seed,
                                      turn_degrees=turn_degrees)
    keep = {k: v for k, v in gt.items() if k not in _HEAVY}
    keep.update(bench_key=np.array(key), major_joints=gt["posed_heads"][:, gt["major_joint_bones"]])
    intr = cam.preset(CAMERA, tuple(resolution))
    os.makedirs(out_dir, exist_ok=True)
    for name in os.listdir(out_dir):               # frames of an earlier, longer recording
        if re.fullmatch(r"depth_\d{4,}\.png", name):
            os.remove(os.path.join(out_dir, name))
    generate_depth(out_dir, posed, faces, keep, resolution=resolution, camera=CAMERA,
                   placement=whole_body_placement(posed, intr), noise=NoiseParams(), floor=True, seed=seed)
    save_bundle(os.path.join(out_dir, "model.npz"), _model(gt), provenance={
        "generator": "articula.sample_scenes.depth_bench", "rig": rig, "skin": "hybrid",
        "subject_seed": int(subject_seed), "macros": json.loads(str(gt["macros"]))})


def _model(g) -> Model:
    sk = Skeleton([str(n) for n in g["bone_names"]], g["parents"], g["heads"], g["tails"], g["frames"])
    return Model(g["rest_vertices"], g["faces"], sk, g["anchor"], g["twist_weights"], g["swing_weights"])


def bench_recording(out_dir, subject_seed: int, resolution=(320, 240), frames: int = 64, seed: int = 0,
                    rig: str = "cmu_mb", turn_degrees: float = 40.0) -> dict:
    """Write (or reuse, when its ``bench_key`` matches) a turning subject's depth recording in ``out_dir``.

    subject_seed: the adult macros (``subjects.resolve_macros``); seed: the limb motion and the sensor noise;
    resolution: (width, height) of the Kinect v1.  Returns a dict: ``out_dir``, ``intrinsics``,
    ``ground_truth``, ``model_path`` and ``depth_paths`` (paths); ``model`` (the subject's hybrid ``Model``,
    the exact model, as ``Subject.hybrid_model()``); ``joints`` (N, 14, 3) world metres (major joints,
    bone heads), ``joint_labels`` (14,) and ``joint_bones`` (14,); ``cam_to_world`` (4, 4); ``reused``;
    ``seconds`` (generation time, 0 when reused).
    """
    out_dir = os.fspath(out_dir)
    key = bench_key(subject_seed, resolution, frames, seed, rig, turn_degrees)
    reused, t0 = _cached(out_dir, key, frames), time.perf_counter()
    if not reused:
        _render(out_dir, key, subject_seed, resolution, frames, seed, rig, turn_degrees)
    seconds = 0.0 if reused else time.perf_counter() - t0
    gt_path, intr_path = os.path.join(out_dir, "ground_truth.npz"), os.path.join(out_dir, "intrinsics.json")
    with np.load(gt_path) as g:
        out = dict(model=_model(g), joints=g["major_joints"].astype(np.float64),
                   joint_labels=tuple(str(x) for x in g["major_joint_labels"]),
                   joint_bones=g["major_joint_bones"].astype(np.int64))
    return dict(out, out_dir=out_dir, intrinsics=intr_path, ground_truth=gt_path,
                model_path=os.path.join(out_dir, "model.npz"),
                depth_paths=[os.path.join(out_dir, f"depth_{k:04d}.png") for k in range(frames)],
                cam_to_world=cam.load_camera_pose(intr_path), reused=reused, seconds=seconds)
