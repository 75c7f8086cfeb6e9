"""Batch command ``import-scans``: scans -> a scan-sequence object, optionally saved to a .blend.

    ./run import-scans --scans scans/ --blend out.blend
    ./run import-scans --scans a.obj b.obj c.obj
    ./run import-scans --scans anim.pc2 --base base.obj --blend out.blend
    blender -b -P batch.py -- import-scans --scans capture.abc --blend out.blend

With ``--blend`` the (empty or opened) file is first saved there, so the frame cache is written next
to it (``<name>_articula/``) and referenced relative to it.
"""
import os

import bpy

from ...solver.errors import ArticulaInputError
from .common import call_operator, finish, save_blend_first


def run(args) -> int:
    scans = [os.path.abspath(p) for p in args.scans]
    if args.blend:
        save_blend_first(args.blend)
    props = dict(frame_start=args.frame_start, require_registered=args.require_registered)
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
    return finish(f"{ob.name}: {data.frame_count} frames of {len(ob.data.vertices)} vertices, "
                  f"{'registered' if data.registered else 'unregistered'}, cache {data.cache_file}",
                  args.blend, saved_first=True)


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
    p.add_argument("--blend", help="save the result to this .blend file")
    p.set_defaults(func=run)
