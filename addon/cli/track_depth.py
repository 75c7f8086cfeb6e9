"""Batch command ``track --depth``: a depth recording (16-bit PNG or EXR frames) + a model bundle or the
built-in template body -> a tracked bundle, + report, + .blend (the ``track`` parser is in :mod:`.track`).

    ./run track --depth rec/ --out tracked.npz --report tracked.json          (template, rec/intrinsics.json)
    ./run track --depth kinect/ --camera kinect_v1 --frames 0:8 --out tracked.npz --blend tracked.blend
    ./run track --model person.npz --depth rec/ --tracker gmm --out tracked.npz

TRACKED.npz holds the model (the template adapted to the person, or the given model with its bone names)
and one pose per tracked depth frame, in order, in the world of ``intrinsics.json``'s optional
``cam_to_world`` (4x4 row-major, metres), else in the camera frame (OpenCV: +X right, +Y down, +Z
forward).  ``--camera`` names the camera of a folder without ``intrinsics.json``.  ``--blend`` imports
the recording with ``articula.import_depth`` (whose world is the fitted floor's: Z up, the camera above
the origin) and puts the tracked rig over it at ``depth object matrix @ inv(cam_to_world)``, the
recording's camera as the scene camera.
"""
import os

import bpy
import numpy as np

from ...solver.depth import camera as cam
from ...solver.errors import ArticulaInputError
from ...solver.formats.axes import AUTO
from ...solver.track.options import TrackOptions
from ...solver.track_depth.options import PERSON_CHOICES, TRACKERS, DepthTrackOptions
from .. import jobs
from ..track import inputs
from ..track_depth import inputs as depth_inputs
from ..track_depth import result, solve
from ..track_depth.report import report_document, summary_text
from ..tracking.result import check_output_path
from .common import call_operator, check_blend_output, editing, finish, write_json

# --camera: the names of solver.depth.camera.CAMERA_PRESETS (older spellings read by cam.preset_key)
CAMERAS = tuple(cam.PRESETS)


def add_arguments(p) -> None:
    """The ``track`` command's depth flags."""
    p.add_argument("--depth", metavar="DIR", help="a depth recording: a folder of 16-bit PNG (millimetres, or "
                                                  "intrinsics.json's depth_unit_m) or EXR (metres) depth frames "
                                                  "with intrinsics.json, or give --camera")
    p.add_argument("--camera", type=cam.preset_key, choices=CAMERAS, metavar="PRESET",
                   help=f"with --depth: the camera of a folder without intrinsics.json ({', '.join(CAMERAS)})")
    p.add_argument("--tracker", type=str.lower, choices=TRACKERS,
                   help=f"with --depth: the per-frame fit (default {DepthTrackOptions().tracker})")
    p.add_argument("--person", type=str.lower, choices=PERSON_CHOICES,
                   help="with --depth and several people in view: whom to track from the start (default "
                        f"{DepthTrackOptions().person}: the one nearest the image's centre; then followed)")


def refuse_scan_flags(args) -> None:
    """Flags of the capture tracker given with ``--depth`` are refused, naming them."""
    default = TrackOptions()
    given = [flag for flag, on in (("--start-pose", args.start_pose), ("--no-adapt", args.no_adapt),
                                   ("--no-temporal", args.no_temporal), ("--fit-scale", args.fit_scale),
                                   ("--adapt", args.adapt != default.adapt), ("--prior", args.prior != default.prior),
                                   ("--max-points", args.max_points != default.max_points),
                                   ("--forward", args.forward != AUTO), ("--up", args.up != AUTO)) if on]
    if given:
        raise ArticulaInputError(f"{', '.join(given)}: for --scans only; the depth tracker does not take "
                                 f"{'it' if len(given) == 1 else 'them'}")


def run(args) -> int:
    refuse_scan_flags(args)
    for path in (args.out, args.report):
        check_output_path(path or "")
    check_blend_output(args.blend)
    default = DepthTrackOptions()
    options = DepthTrackOptions(tracker=args.tracker or default.tracker,
                                person=args.person or default.person).validate()
    if args.model:
        model_input = inputs.model_from_bundle(os.path.abspath(args.model))
        model_input.matrix = np.eye(4)
    else:
        model_input = depth_inputs.template_input()
    camera = args.camera or None
    captures = depth_inputs.recording_from_folder(args.depth, camera, args.frames)
    if camera and _has_intrinsics(args.depth):
        print(f"{args.depth}: intrinsics.json found; --camera {args.camera} not used")
    outcome = solve.track(model_input, captures, options, jobs.Progress("track", echo=True))
    result.save(args.out, outcome)
    for note in outcome.result.notes:
        print(f"{os.path.basename(captures.label)}: {note}")
    print(f"wrote {args.out}: {outcome.model.num_vertices} vertices, {outcome.model.skeleton.num_bones} bones, "
          f"{len(outcome.poses)} poses ({captures.coordinates}); {summary_text(outcome)}")
    if args.report:
        write_json(args.report, report_document(outcome))
        print(f"wrote {args.report}")
    if args.blend:
        _save_blend(os.path.abspath(args.blend), outcome, camera)
    return 0


def _has_intrinsics(folder: str) -> bool:
    return os.path.isfile(os.path.join(os.path.abspath(folder), "intrinsics.json"))


def blend_matrix(depth_object_matrix, cam_to_world) -> np.ndarray:
    """(4, 4) where the tracked rig stands in the .blend: the imported depth object maps sensor-frame
    points (OpenCV axes) into Blender's world, the tracked poses are in ``cam_to_world``'s frame (sensor
    -> tracking frame), so tracking frame -> Blender world = object matrix @ inv(cam_to_world)."""
    return np.asarray(depth_object_matrix, np.float64) @ np.linalg.inv(np.asarray(cam_to_world, np.float64))


def _save_blend(blend: str, outcome, camera) -> None:
    """Import the recording (frames 1..N) and put the tracked rig over it, seen through its camera; saved
    to ``blend`` (added to it when it exists)."""
    cap = outcome.captures
    props = dict(directory=cap.label, frame_start=1)
    if not _has_intrinsics(cap.label):
        props["preset"] = camera
    with editing(blend):
        call_operator(bpy.ops.articula.import_depth, **props)
        ob = bpy.context.view_layer.objects.active
        outcome.model_input.matrix = blend_matrix(ob.matrix_world, cap.recording.camera.cam_to_world)
        cam_ob = depth_inputs.camera_object(ob)
        cap.object_name, cap.frame_start = ob.name, 1
        cap.camera_name = cam_ob.name if cam_ob is not None else ""
        with jobs.scene_guard():
            arm, action, _warnings = result.build(bpy.context, outcome)
            result.look_through(bpy.context, cap.camera_name)
        finish(f"{arm.name}: action {action.name!r} on frames {1 + outcome.first_frame}.."
               f"{outcome.first_frame + len(outcome.poses)} over {ob.name!r}", blend)
