"""``demo``: Articula's main job on its embedded default data, end to end through the real operators.

1. builds the sample data (``sample_scenes``): a MakeHuman subject (``cmu_mb`` rig, hybrid skin) in a
   short range-of-motion sequence written as OBJ scans with its ground-truth model bundle, and a depth
   recording of a walk seen by a Kinect-v1-like camera;
2. in a new scene imports the scans (``articula.import_scans``) and the depth recording
   (``articula.import_depth``), builds the exact swing/twist rig from the bundle with its poses baked
   (``articula.build_rig``);
3. learns a rig from the imported scan-sequence object alone (``articula.learn_rig``: skeleton,
   swing/twist weights and rest mesh, one baked pose per scan, the per-vertex error as a heat map) and
   prints its error statistics (``--no-learn`` skips this; ``--parts`` and ``--learn-iterations`` set
   the learner's part count and outer rounds);
4. tracks a short unregistered recording of the same subject (noisy 4-view scans of a walk, imported
   by ``articula.import_scans`` as an unregistered sequence) with the learned rig (``articula.track``
   on the rig saved as a bundle, so the tracked rig is built beside the learned one; no adaptation on
   so short a recording), ``--track-frames`` frames (0 skips this);
5. lays the results out side by side (depth recording, ground-truth rig, scans, learned rig, tracked
   rig over its captures), saves
   ``<out>/demo.blend`` and renders ``<out>/demo.png`` (Workbench, headless; the learned rig in its
   heat-map colours, blue 0 mm to red at the largest error);
6. prints one summary line with the numbers the README's caption quotes (:func:`summary_line`).
"""
from __future__ import annotations

import json
import os
import time

import bpy
import numpy as np

from ...sample_scenes.depth_recording import generate_depth
from ...sample_scenes.registered import generate_registered, posed_sequence
from ...sample_scenes.unregistered import generate_unregistered
from ...solver.errors import ArticulaInputError
from ...solver.learn.options import MIN_SCANS
from ...solver.rig import names as rig_names
from ..learn import heat_map
from ..learn import report as learn_report
from ..scene import frames, render
from ..sequences import scans as scan_sequence
from .common import save_blend

SPACING = 1.1  # metres between the demo's exhibits along X
LEARNED_NAME = "Learned rig"
DEFAULT_PARTS = 0          # learn_rig's part count in the demo (0: chosen from the motion)
DEFAULT_ITERATIONS = 3     # learn_rig's outer rounds in the demo (the operator's default is 10)
TRACKED_NAME = "Tracked rig"
DEFAULT_TRACK_FRAMES = 4   # frames of the unregistered recording the demo tracks
TITLES = {"depth": "Depth recording", "rig": "Articula rig (baked poses)", "scans": "Registered scans",
          "tracked": "Tracked rig over unregistered scans"}


def learned_title(scale_mm: float) -> str:
    """The learned rig's label, with the heat map's range (blue 0 mm to red ``scale_mm``)."""
    return f"Learned rig (error heat map, 0-{scale_mm:.0f} mm)"


def _stage(name: str, t0: float, times: dict = None, key: str = "") -> float:
    """Print a stage's line with its wall time (s) since ``t0``; record it in ``times[key]`` when given."""
    now = time.perf_counter()
    print(f"demo: {name} ({now - t0:.1f} s)", flush=True)
    if times is not None and key:
        times[key] = now - t0
    return now


def summary_line(learned: dict, tracked: dict, times: dict, total_s: float) -> str:
    """The numbers the README's caption quotes, in one line: the learned rig's bones and error (mm), the
    tracked frames' median distance (mm), and each stage's wall time with the total (s)."""
    parts = []
    if learned:
        err = ", ".join(f"{k} {learned[k]:.2f}" for k in ("mean", "median", "max") if k in learned)
        parts.append(f"learned rig {learned['bones']} control bones, error (mm) {err}, heat map "
                     f"0-{learned['scale']:.0f} mm")
    if tracked:
        med = tracked.get("median_mm")
        parts.append(f"tracked {len(tracked.get('frames', []))} frames, median "
                     f"{'n/a' if med is None else f'{med:.2f}'} mm")
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
    parts.append(f"times: {stages}; total {total_s:.1f} s")
    return "demo: summary: " + "; ".join(parts)


def make_data(data_dir: str, n_scans: int, n_depth: int, seed: int = 0, n_track: int = 0) -> dict:
    """Write the demo's sample data below ``data_dir``; return the paths."""
    scans = os.path.join(data_dir, "scans")
    depth = os.path.join(data_dir, "depth")
    unreg = os.path.join(data_dir, "unregistered")
    if n_track:
        walk, faces, gt = posed_sequence(rig="cmu_mb", shape="female", n_poses=n_track, motion="walk",
                                         skin="hybrid", seed=seed)
        generate_unregistered(unreg, walk, faces, gt, seed=seed, fmt="ply")
    generate_registered(scans, rig="cmu_mb", shape="female", n_poses=n_scans, motion="rom",
                        skin="hybrid", fmt="obj", seed=seed)
    frames, faces, gt = posed_sequence(rig="cmu_mb", shape="male", n_poses=n_depth, motion="walk",
                                       skin="hybrid", seed=seed)
    generate_depth(depth, frames, faces, gt, resolution=(320, 240), seed=seed)
    return {"scans": scans, "depth": depth, "unregistered": unreg if n_track else None,
            "bundle": os.path.join(scans, "ground_truth_model.npz")}


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


def build_scene(paths: dict) -> dict:
    """Import and build everything into a new empty scene (its caches move beside the .blend when that
    is saved); return the created objects by role."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scans = _call(bpy.ops.articula.import_scans, directory=paths["scans"])
    depth = _call(bpy.ops.articula.import_depth, directory=paths["depth"],
                  intrinsics=os.path.join(paths["depth"], "intrinsics.json"), remove_floor=True)
    _place_depth_camera(depth, os.path.join(paths["depth"], "ground_truth.npz"))
    rig = _call(bpy.ops.articula.build_rig, filepath=paths["bundle"])
    _shift(scans, SPACING)
    _shift(depth, -SPACING)
    return {"scans": scans, "depth": depth, "rig": rig}


def cover_sequences(scene, objects) -> None:
    """Widen the scene's frame range to every sequence object among ``objects`` (baking a rig's poses,
    the built one's and the learned one's, sets it to the poses' frames, fewer than the depth
    recording's)."""
    for ob in objects:
        data = ob.articula
        if ob.type == 'MESH' and data.kind != 'NONE' and data.frame_count:
            frames.include_frames(scene, data.frame_start, data.frame_start + data.frame_count - 1)


def learn_scene(scans: list, parts: int = 0, iterations: int = 2, seed: int = 0) -> tuple:
    """Learn a rig from the imported scan-sequence object (one of ``scans``) with ``articula.learn_rig``
    and place it beside the scans; return ``(objects, report)``, the report being the solver's report
    the operator stored on the armature (``articula_learn_report``)."""
    seqs = [ob for ob in scans if scan_sequence.is_scan_sequence(ob)]
    if not seqs:
        raise ArticulaInputError("demo: the scan import made no scan-sequence object to learn from")
    objects = _call(bpy.ops.articula.learn_rig, source_object=seqs[0].name, name=LEARNED_NAME, parts=parts,
                    max_iterations=iterations, seed=seed)
    arms = [ob for ob in objects if ob.type == 'ARMATURE' and learn_report.REPORT_PROPERTY in ob]
    if len(arms) != 1:
        raise ArticulaInputError(f"demo: articula.learn_rig made {len(arms)} armatures with a report, expected 1")
    # The learned rig gets the scans object's matrix (it stands where the scans stand): one spacing on.
    _shift(objects, SPACING)
    return objects, json.loads(arms[0][learn_report.REPORT_PROPERTY])


def track_scene(learned: list, unregistered: str, bundle_path: str) -> tuple:
    """Import the unregistered scans three spacings on (beside the learned rig), save the learned rig as a bundle and track the scans
    with it (``articula.track``); return ``(objects, report)`` (the tracker's report on the new rig)."""
    arms = [ob for ob in learned if ob.type == 'ARMATURE']
    _call(bpy.ops.articula.export_bundle, filepath=bundle_path, armature=arms[0].name)
    captures = _call(bpy.ops.articula.import_scans, directory=unregistered)
    _shift(captures, 3 * SPACING)
    seqs = [ob for ob in captures if scan_sequence.is_scan_sequence(ob)]
    if not seqs:
        raise ArticulaInputError("demo: the unregistered scans made no scan-sequence object to track")
    tracked = _call(bpy.ops.articula.track, bundle=bundle_path, captures=seqs[0].name, adapt='OFF',
                    name=TRACKED_NAME)
    rigs = [ob for ob in tracked if ob.type == 'ARMATURE' and "articula_track_report" in ob]
    if len(rigs) != 1:
        raise ArticulaInputError(f"demo: articula.track made {len(rigs)} armatures with a report, expected 1")
    return captures + tracked, json.loads(rigs[0]["articula_track_report"])


def tracked_summary(report: dict) -> str:
    """One line about a tracking run: frames, median scan-to-model distance, lost and skipped frames."""
    med = report.get("median_mm")
    return (f"{len(report.get('frames', []))} frames, median scan-to-model "
            f"{'n/a' if med is None else f'{med:.2f} mm'}, lost {report.get('lost_frames')}, "
            f"skipped {report.get('skipped_frames')}, prior {report.get('prior')}")


def _heat_scale(objects) -> float:
    """The error (mm) the top (red) colour of the learned mesh's heat map stands for."""
    return max(float(ob.data.get(heat_map.SCALE_PROPERTY, 0.0)) for ob in objects if ob.type == 'MESH')


def learned_numbers(objects, report: dict) -> dict:
    """The learned rig's control bones (one per part; the swing helpers are not counted), its error
    statistics (mm: mean, median, max) and its heat map's top (mm)."""
    arm = next(ob for ob in objects if ob.type == 'ARMATURE' and learn_report.REPORT_PROPERTY in ob)
    bones = sum(rig_names.BONE_INDEX_PROP in bone for bone in arm.data.bones)
    return dict(learn_report.error_summary(report), bones=bones, scale=_heat_scale(objects))


def learned_summary(report: dict) -> str:
    """One line about a learned rig: parts, rounds and its error statistics (mm)."""
    s = learn_report.error_summary(report)
    err = ", ".join(f"{k} {s[k]:.2f}" for k in ("mean", "median", "max") if k in s)
    return (f"{report.get('parts', '?')} parts, {report.get('iterations', '?')} rounds; "
            f"error (scan vertex to learned surface, mm) {err or 'n/a'}")


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
    width, height = _resolution(args.resolution)
    if not args.no_learn:
        if args.scans < MIN_SCANS:
            raise ArticulaInputError(f"--scans {args.scans}: learning a rig needs at least {MIN_SCANS} scans "
                                     f"(or --no-learn)")
        if args.parts < 0 or args.learn_iterations < 0:
            raise ArticulaInputError("--parts and --learn-iterations must be 0 or more")
    if args.track_frames is None:
        args.track_frames = 0 if args.no_learn else DEFAULT_TRACK_FRAMES
    if args.track_frames < 0 or (args.track_frames and args.no_learn):
        raise ArticulaInputError("--track-frames must be 0 or more, and tracking needs the learned rig "
                                 "(not with --no-learn)")
    t0 = time.perf_counter()
    paths = make_data(os.path.join(out, "demo_data"), args.scans, args.depth_frames, args.seed,
                      args.track_frames)
    times, learned, track_report = {}, {}, {}
    t = _stage("sample data written", t0, times, "sample data")
    blend = os.path.join(out, "demo.blend")
    built = build_scene(paths)
    t = _stage(f"imported and built ({', '.join(f'{k}: {len(v)} objects' for k, v in built.items())})", t,
               times, "import and build")
    titles = dict(TITLES)
    if not args.no_learn:
        parts = f"{args.parts} parts" if args.parts else "parts chosen from the motion"
        print(f"demo: learning a rig from {args.scans} scans ({parts}, at most {args.learn_iterations} "
              f"rounds)", flush=True)
        built["learned"], report = learn_scene(built["scans"], args.parts, args.learn_iterations, args.seed)
        learned = learned_numbers(built["learned"], report)
        titles["learned"] = learned_title(learned["scale"])
        t = _stage(f"learned rig {LEARNED_NAME!r}: {learned_summary(report)}", t, times, "learning")
        if args.track_frames:
            print(f"demo: tracking {args.track_frames} unregistered scans with the learned rig", flush=True)
            built["tracked"], track_report = track_scene(built["learned"], paths["unregistered"],
                                                         os.path.join(out, "demo_data", "learned.npz"))
            t = _stage(f"tracked rig {TRACKED_NAME!r}: {tracked_summary(track_report)}", t, times, "tracking")
    scene = bpy.context.scene
    cover_sequences(scene, built["scans"] + built["depth"] + built.get("tracked", []))
    scene.frame_set(max(1, args.scans // 2))
    png = os.path.join(out, "demo.png")
    coloured = [titles[k] for k in ("learned", "tracked") if k in built]     # heat map, capture error colours
    render.render_overview(scene, png, {titles[k]: v for k, v in built.items()}, coloured, width, height)
    t = _stage(f"rendered {png}", t, times, "rendering")
    save_blend(blend)
    _stage(f"saved {blend}", t, times, "saving")
    print(summary_line(learned, track_report, times, time.perf_counter() - t0))
    print(f"demo: done in {time.perf_counter() - t0:.1f} s -> {blend}, {png}")
    return 0


def _resolution(text: str) -> tuple:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ArticulaInputError(f"--resolution: expected WIDTHxHEIGHT such as 1280x720, got {text!r}") from None
    if w < 16 or h < 16:
        raise ArticulaInputError(f"--resolution: {text!r} is too small (at least 16x16)")
    return w, h


def add_commands(sub) -> None:
    p = sub.add_parser("demo", help="build the sample data, import it, build the rig, learn a rig from the "
                                    "scans, render out/demo.png")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--scans", type=int, default=12, help="registered scans to generate (default 12)")
    p.add_argument("--depth-frames", type=int, default=30, help="depth frames to generate (default 30)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-learn", action="store_true", help="do not learn a rig from the scans")
    p.add_argument("--parts", type=int, default=DEFAULT_PARTS,
                   help=f"parts (bones) of the learned rig; 0 lets the learner choose from the motion, which "
                        f"takes longer (default {DEFAULT_PARTS})")
    p.add_argument("--learn-iterations", type=int, default=DEFAULT_ITERATIONS,
                   help=f"at most this many outer rounds of the learner (default {DEFAULT_ITERATIONS})")
    p.add_argument("--track-frames", type=int, default=None,
                   help=f"frames of the unregistered recording tracked with the learned rig; 0 skips tracking "
                        f"(default {DEFAULT_TRACK_FRAMES}, 0 with --no-learn)")
    p.add_argument("--resolution", default="1280x720", help="picture size WIDTHxHEIGHT (default 1280x720)")
    p.set_defaults(func=run)
