"""Batch command ``import-depth``: a depth recording or point-cloud sequence -> a point-cloud object
and a matching camera, optionally saved to a .blend.

    ./run import-depth --depth rec/ --blend out.blend                 (rec/intrinsics.json)
    ./run import-depth --depth kinect/ --preset kinect_v1 --voxel 0.01 --blend out.blend
    blender -b -P batch.py -- import-depth --depth rec/ --intrinsics cam.json --subtract-background

With ``--blend`` an existing file is opened and the recording added to it (saved with a ``.blend1`` of
the previous version), else it goes into an empty scene saved there; the point cache is put beside the
file (``//<blend name>_articula/<name>-<id>.points.npz``).  A failed import saves nothing.
"""
import os

import bpy

from ...solver.depth import camera
from .common import call_operator, editing, finish



def run(args) -> int:
    with editing(args.blend):
        return _import(args)


def _import(args) -> int:
    props = dict(directory=os.path.abspath(args.depth), depth_min=args.depth_min, depth_max=args.depth_max,
                 remove_floor=not args.keep_floor, floor_tolerance=args.floor_tolerance,
                 subtract_background=args.subtract_background or bool(args.background),
                 background_frames=args.background_frames, background_tolerance=args.background_tolerance,
                 depth_noise=args.depth_noise,
                 voxel_size=args.voxel, estimate_normals=not args.no_normals, frame_start=args.frame_start,
                 point_radius=args.radius)
    if args.intrinsics:
        props["intrinsics"] = os.path.abspath(args.intrinsics)
    if args.preset:
        props["preset"] = args.preset
    if args.depth_scale is not None:
        props["depth_scale"] = args.depth_scale
    if args.background:
        props["background"] = os.path.abspath(args.background)
    if args.color:
        props["color_directory"] = os.path.abspath(args.color)
    if args.cache:
        props["cache_file"] = os.path.abspath(args.cache)
    if args.name:
        props["collection_name"] = args.name
    call_operator(bpy.ops.articula.import_depth, **props)
    ob = bpy.context.view_layer.objects.active
    code = finish(f"{ob.name}: {ob.articula.frame_count} frames", args.blend)
    if args.blend:
        print(f"cache {ob.articula.cache_file}")       # where it is once saved
    return code


def add_commands(sub):
    p = sub.add_parser("import-depth", help="import a depth recording (16-bit PNG/EXR frames) or a point-cloud "
                                            "sequence (PLY/XYZ/NPY) as a point-cloud object with a camera")
    p.add_argument("--depth", required=True, metavar="FOLDER", help="folder of depth or point-cloud frames")
    cam = p.add_mutually_exclusive_group()
    cam.add_argument("--intrinsics", metavar="FILE", help="intrinsics.json (default: the one in the folder)")
    cam.add_argument("--preset", type=camera.preset_key, choices=tuple(camera.PRESETS),
                     help=f"nominal camera model ({', '.join(camera.PRESETS)})")
    p.add_argument("--depth-scale", type=float, help="metres per PNG unit (default: the intrinsics' "
                                                     "depth_unit_m, 0.001)")
    p.add_argument("--depth-min", type=float, default=0.3, help="metres (default 0.3)")
    p.add_argument("--depth-max", type=float, default=5.0, help="metres (default 5)")
    p.add_argument("--keep-floor", action="store_true", help="do not fit and remove the floor plane")
    p.add_argument("--floor-tolerance", type=float, default=0.02, help="metres (default 0.02)")
    p.add_argument("--subtract-background", action="store_true",
                   help="remove the static background (median of the first frames, or --background)")
    p.add_argument("--background", metavar="FILE", help="depth frame of the empty scene")
    p.add_argument("--background-frames", type=int, default=10)
    p.add_argument("--background-tolerance", type=float, default=0.05, help="metres (default 0.05)")
    p.add_argument("--depth-noise", type=float, default=0.01,
                   help="floor/background tolerances grow by this times depth^2 along the ray, 1/m "
                        "(default 0.01; 0 = fixed tolerances)")
    p.add_argument("--voxel", type=float, default=0.0, help="voxel size in metres (0 = keep all points)")
    p.add_argument("--no-normals", action="store_true", help="do not store per-point normals")
    p.add_argument("--color", metavar="FOLDER", help="colour frames (PNG/JPG) registered to the depth frames")
    p.add_argument("--frame-start", type=int, default=1)
    p.add_argument("--radius", type=float, default=0.004, help="displayed point radius in metres")
    p.add_argument("--cache", metavar="FILE", help="where to write the point cache (.npz)")
    p.add_argument("--name", default="", help="collection name (default: the folder name)")
    p.add_argument("--blend", help="save the result to this .blend file")
    p.set_defaults(func=run)
