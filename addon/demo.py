"""``demo``: Articula's main job on its embedded default data, end to end through the real operators.

1. builds the sample data (``sample_scenes``): a MakeHuman subject (``cmu_mb`` rig, hybrid skin) in a
   short range-of-motion sequence written as OBJ scans with its ground-truth model bundle, and a depth
   recording of a walk seen by a Kinect-v1-like camera;
2. in a new scene imports the scans (``articula.import_scans``) and the depth recording
   (``articula.import_depth``), builds the exact swing/twist rig from the bundle with its poses baked
   (``articula.build_rig``);
3. lays the results out side by side, saves ``<out>/demo.blend`` and renders ``<out>/demo.png``
   (Workbench, headless).
"""
from __future__ import annotations

import os
import time

import bpy
import numpy as np

from ..sample_scenes.depth_recording import generate_depth
from ..sample_scenes.registered import generate_registered, posed_sequence
from ..solver.errors import ArticulaInputError
from . import render
from .cli import save_blend_again, save_blend_first

SPACING = 1.1  # metres between the demo's exhibits along X


def _stage(name: str, t0: float) -> float:
    now = time.perf_counter()
    print(f"demo: {name} ({now - t0:.1f} s)", flush=True)
    return now


def make_data(data_dir: str, n_scans: int, n_depth: int, seed: int = 0) -> dict:
    """Write the demo's sample data below ``data_dir``; return the paths."""
    scans = os.path.join(data_dir, "scans")
    depth = os.path.join(data_dir, "depth")
    generate_registered(scans, rig="cmu_mb", shape="female", n_poses=n_scans, motion="rom",
                        skin="hybrid", fmt="obj", seed=seed)
    frames, faces, gt = posed_sequence(rig="cmu_mb", shape="male", n_poses=n_depth, motion="walk",
                                       skin="hybrid", seed=seed)
    generate_depth(depth, frames, faces, gt, resolution=(320, 240), seed=seed)
    return {"scans": scans, "depth": depth, "bundle": os.path.join(scans, "ground_truth_model.npz")}


def _new_objects(before: set) -> list:
    return [ob for ob in bpy.data.objects if ob.as_pointer() not in before]


def _call(op, **kwargs) -> list:
    """Run an operator; return the objects it created."""
    before = {ob.as_pointer() for ob in bpy.data.objects}
    if op(**kwargs) != {'FINISHED'}:
        raise ArticulaInputError(f"{op.idname_py()} did not finish")
    return _new_objects(before)


def _roots(objects) -> list:
    return [ob for ob in objects if ob.parent is None or ob.parent not in objects]


def _shift(objects, dx: float) -> None:
    for ob in _roots(objects):
        ob.matrix_world.translation.x += dx


def build_scene(paths: dict, blend: str) -> dict:
    """Import and build everything into a new empty scene saved as ``blend`` first (so the importers'
    frame caches go next to it); return the created objects by role."""
    bpy.ops.wm.read_homefile(use_empty=True)
    save_blend_first(blend)
    scans = _call(bpy.ops.articula.import_scans, directory=paths["scans"])
    depth = _call(bpy.ops.articula.import_depth, directory=paths["depth"],
                  intrinsics=os.path.join(paths["depth"], "intrinsics.json"), remove_floor=True)
    _place_depth_camera(depth, os.path.join(paths["depth"], "ground_truth.npz"))
    rig = _call(bpy.ops.articula.build_rig, filepath=paths["bundle"])
    _shift(scans, SPACING)
    _shift(depth, -SPACING)
    return {"scans": scans, "depth": depth, "rig": rig}


def _place_depth_camera(objects, gt_path: str) -> None:
    """Put the imported depth camera where the generator's camera was, so the points sit on the body."""
    from mathutils import Matrix
    cams = [ob for ob in objects if ob.type == 'CAMERA']
    if cams and os.path.exists(gt_path):
        with np.load(gt_path) as gt:
            cams[0].matrix_world = Matrix(gt["blender_camera_matrix"][0].tolist())


def run(args) -> int:
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    t0 = time.perf_counter()
    paths = make_data(os.path.join(out, "demo_data"), args.scans, args.depth_frames, args.seed)
    t = _stage("sample data written", t0)
    blend = os.path.join(out, "demo.blend")
    built = build_scene(paths, blend)
    t = _stage(f"imported and built ({', '.join(f'{k}: {len(v)} objects' for k, v in built.items())})", t)
    scene = bpy.context.scene
    scene.frame_set(max(1, args.scans // 2))
    png = os.path.join(out, "demo.png")
    titles = {"depth": "Depth recording", "rig": "Articula rig (baked poses)", "scans": "Registered scans"}
    render.render_overview(scene, png, {titles[k]: v for k, v in built.items()})
    t = _stage(f"rendered {png}", t)
    save_blend_again()
    _stage(f"saved {blend}", t)
    print(f"demo: done in {time.perf_counter() - t0:.1f} s -> {blend}, {png}")
    return 0


def add_commands(sub) -> None:
    p = sub.add_parser("demo", help="build the sample data, import it, build the rig, render out/demo.png")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--scans", type=int, default=12, help="registered scans to generate (default 12)")
    p.add_argument("--depth-frames", type=int, default=30, help="depth frames to generate (default 30)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=run)
