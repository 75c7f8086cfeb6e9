"""Batch command ``bind-scan``: bind a detailed scan to an Articula rig in a .blend (as the operator
``articula.bind_scan`` does) and save the result as another .blend.

    ./run bind-scan --blend rig.blend --rig Body --scan scan.ply --out out/scan_bound.blend
    ./run bind-scan --blend rig.blend --scan scan.obj --frame 12 --out out/bound.blend     (pose of frame 12)
    ./run bind-scan --blend rig.blend --scan ScanObject --bind-pose rest --out out/bound.blend

``--scan`` is a mesh file (OBJ, PLY, STL, OFF; axes as ``import-scans``: OBJ forward -Z up Y, the others as
written; ``--forward`` / ``--up``) imported as a new object, or the name of a mesh object in ``--blend``.
``--blend`` itself is never written; a command that fails saves nothing.
"""
import os

import bpy
from mathutils import Matrix

from ...solver.errors import ArticulaInputError
from ...solver.formats import axes, mesh_files
from ..retarget import scan_binding
from ..sequences.scans import set_geometry
from .common import call_operator, check_blend_output, finish, open_blend
from .scans import add_axis_arguments


def _check(args) -> None:
    """Validate the arguments before opening anything."""
    if not os.path.isfile(args.blend):
        raise ArticulaInputError(f"{args.blend}: no such .blend file")
    if os.path.normpath(os.path.abspath(args.out)) == os.path.normpath(os.path.abspath(args.blend)):
        raise ArticulaInputError(f"--out {args.out}: give another file than --blend (it is never replaced)")
    if os.path.splitext(args.out)[1].lower() != ".blend":
        raise ArticulaInputError(f"--out {args.out}: must be a .blend file")
    check_blend_output(args.out)
    if _is_file(args.scan):
        mesh_files.check_mesh(args.scan)


def _is_file(scan: str) -> bool:
    return os.path.splitext(scan)[1].lower() in mesh_files.MESH_EXTENSIONS or os.path.sep in scan


def _import_scan(args) -> bpy.types.Object:
    """A new mesh object from the scan file, stood up in Blender's axes; linked to the scene."""
    mesh = mesh_files.read_mesh(args.scan)
    name = args.name or os.path.splitext(os.path.basename(args.scan))[0]
    me = bpy.data.meshes.new(name)
    set_geometry(me, mesh.vertices, mesh.face_sizes, mesh.corner_verts)
    ob = bpy.data.objects.new(name, me)
    ob.matrix_world = Matrix(axes.conversion(os.path.splitext(args.scan)[1], args.forward, args.up).tolist())
    bpy.context.scene.collection.objects.link(ob)
    return ob


def bind_scan(args) -> int:
    _check(args)
    open_blend(args.blend)
    if args.frame is not None:
        bpy.context.scene.frame_set(args.frame)
    scan = _import_scan(args) if _is_file(args.scan) else scan_binding.find_scan(args.scan)
    call_operator(bpy.ops.articula.bind_scan, scan=scan.name, rig=args.rig, bind_pose=args.bind_pose.upper())
    mod = scan.modifiers.get(scan_binding.MODIFIER)
    return finish(f"bound {scan.name!r} ({len(scan.data.vertices):,} vertices) to {mod.target.name!r} "
                  f"at frame {bpy.context.scene.frame_current} ({args.bind_pose} pose)", args.out)


def add_commands(sub):
    p = sub.add_parser("bind-scan", help="make a detailed scan follow an Articula rig (Surface Deform binding)")
    p.add_argument("--blend", required=True, help=".blend holding the rig (never written)")
    p.add_argument("--scan", required=True,
                   help="scan mesh file (.obj/.ply/.stl/.off), or the name of a mesh object in --blend")
    p.add_argument("--rig", default="", help="rig armature or rig mesh (default: the file's only Articula rig)")
    p.add_argument("--bind-pose", choices=("current", "rest"), default="current",
                   help="the rig's pose in which the scan lies on it: the frame's pose (default) or the rest pose")
    p.add_argument("--frame", type=int, default=None, help="scene frame to bind at (default: the file's frame)")
    p.add_argument("--name", default="", help="name of the imported scan object (default: the file name)")
    add_axis_arguments(p)
    p.add_argument("--out", required=True, help=".blend to save the scene with the bound scan to")
    p.set_defaults(func=bind_scan)
