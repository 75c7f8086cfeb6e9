"""Batch command ``import-scans``: scans -> a scan-sequence object, optionally saved to a .blend.

    ./run import-scans --scans scans/ --blend out.blend
    ./run import-scans --scans a.obj b.obj c.obj
    ./run import-scans --scans anim.pc2 --base base.obj --blend out.blend
    ./run import-scans --scans zup_scans/ --forward Y --up Z      # OBJ files written Z up
    blender -b -P batch.py -- import-scans --scans capture.abc --blend out.blend

With ``--blend`` an existing file is opened and the scans added to it (saved with a ``.blend1`` of the
previous version), else the scans go into an empty scene saved there; the frame cache is put beside the
file (``<blend name>_articula/``) and referenced relative to it.  A failed import saves nothing.
"""
import argparse
import os

import bpy

from ...solver.errors import ArticulaInputError
from ...solver.formats.axes import AUTO, parse_axis
from .common import allow_axis_values, call_operator, editing, finish


def run(args) -> int:
    with editing(args.blend):
        return _import(args)


def _import(args) -> int:
    scans = [os.path.abspath(p) for p in args.scans]
    props = dict(frame_start=args.frame_start, require_registered=args.require_registered, **axis_props(args))
    if args.name:
        props["name"] = args.name
    if args.base:
        props["base_mesh"] = os.path.abspath(args.base)
    if len(scans) == 1:
        props["filepath"] = scans[0]
    else:
        folders = {os.path.dirname(p) for p in scans}
        if len(folders) > 1:
            raise ArticulaInputError("give files from one folder (or the folder itself)")
        props["directory"] = folders.pop()
        props["files"] = [{"name": os.path.basename(p)} for p in scans]
    call_operator(bpy.ops.articula.import_scans, **props)
    ob = bpy.context.view_layer.objects.active
    data = ob.articula
    code = finish(f"{ob.name}: {data.frame_count} frames of {len(ob.data.vertices)} vertices, "
                  f"{'registered' if data.registered else 'unregistered'}", args.blend)
    if args.blend:
        print(f"cache {data.cache_file}")       # where it is once saved
    return code


def _axis(text: str) -> str:
    try:
        return parse_axis(text)
    except ArticulaInputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_axis_arguments(p) -> None:
    """``--forward`` / ``--up`` (X, Y, Z, -X, -Y, -Z or auto) of a command reading scan files."""
    allow_axis_values(p)
    for flag, which in (("--forward", "+Y (forward)"), ("--up", "+Z (up)")):
        p.add_argument(flag, default=AUTO, type=_axis, metavar="AXIS",
                       help=f"the files' axis that becomes Blender's {which}: X, Y, Z, -X, -Y, -Z (default auto: "
                            f"the format's convention, OBJ forward -Z up Y, PLY/STL/OFF/MDD/PC2 as written)")


def axis_props(args) -> dict:
    """The operators' ``axis_forward`` / ``axis_up`` from ``--forward`` / ``--up``."""
    return {"axis_forward": args.forward, "axis_up": args.up}


def add_commands(sub):
    p = sub.add_parser("import-scans", help="import scans (mesh files, a folder, .abc, .mdd/.pc2) as a "
                                            "scan-sequence object")
    p.add_argument("--scans", nargs="+", required=True, metavar="PATH",
                   help="a folder of OBJ/PLY/STL/OFF files, several such files, one .abc, or one .mdd/.pc2")
    p.add_argument("--base", help="mesh file with the faces of a .mdd/.pc2 point cache")
    p.add_argument("--name", default="", help="object name (default: the folder or file name)")
    p.add_argument("--frame-start", type=int, default=1, help="scene frame of the first scan (default 1)")
    p.add_argument("--require-registered", action="store_true",
                   help="fail unless all frames share vertices and faces")
    add_axis_arguments(p)
    p.add_argument("--blend", help="save the result to this .blend file")
    p.set_defaults(func=run)
