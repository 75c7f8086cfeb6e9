"""Batch commands for rigs and actions (see ``./run <command> --help``):

* ``build-rig --bundle X.npz [--blend out.blend] [--name N] [--no-bake] [--frame-start 1]``
* ``bake --bundle X.npz --blend file.blend [--armature NAME] [--nla] [--frame-start 1] [--out other.blend]``
* ``export-bundle --blend file.blend --out X.npz [--armature NAME] [--action NAME] [--no-poses]``

``build-rig --blend`` adds the rig to the file when it exists, else saves it in an empty scene; ``bake``
saves over ``--blend`` (or as ``--out``).  Saving over a file keeps its previous version as ``.blend1``;
a command that fails saves nothing (``common.editing``).
"""
import bpy

from ..rig import bundle_io as rig_io
from ..rig import reader as rig_reader
from .common import check_blend_output, editing, finish, open_blend


def build_rig(args) -> int:
    with editing(args.blend):
        return _build_rig(args)


def _build_rig(args) -> int:
    rig, action = rig_io.build_from_bundle(bpy.context, args.bundle, args.name, not args.no_bake, args.frame_start)
    for text in rig.warnings:
        print(f"warning: {text}")
    frames = f", action {action.name!r}" if action is not None else ""
    return finish(f"built rig {rig.armature.name!r}: {len(rig.mesh.data.vertices)} vertices, "
                  f"{len(rig_reader.control_names(rig.armature))} control bones{frames}", args.blend)


def bake(args) -> int:
    out = args.out or args.blend
    check_blend_output(out)
    open_blend(args.blend)
    action = rig_io.bake_bundle(bpy.context, args.bundle, args.armature, args.nla, args.frame_start,
                                args.action_name, warn=lambda text: print(f"warning: {text}"))
    return finish(f"baked action {action.name!r}", out)


def export_bundle(args) -> int:
    open_blend(args.blend)
    model, poses = rig_io.export_bundle(args.out, args.armature, args.action,
                                        'NONE' if args.no_poses else 'ACTIVE', bpy.context)
    frames = f", {len(poses)} poses" if poses is not None else ""
    return finish(f"wrote {args.out}: {model.num_vertices} vertices, {model.skeleton.num_bones} bones{frames}", scene=False)


def add_commands(sub):
    p = sub.add_parser("build-rig", help="build an Articula rig from a model bundle")
    p.add_argument("--bundle", required=True, help="model bundle (.npz)")
    p.add_argument("--blend", help="save the scene to this .blend")
    p.add_argument("--name", default="", help="rig name (default: the bundle's file name)")
    p.add_argument("--no-bake", action="store_true", help="do not bake the bundle's poses")
    p.add_argument("--frame-start", type=int, default=1)
    p.set_defaults(func=build_rig)

    p = sub.add_parser("bake", help="bake a bundle's poses as a new action on a rig in a .blend")
    p.add_argument("--bundle", required=True, help="bundle with poses (.npz)")
    p.add_argument("--blend", required=True, help=".blend holding the rig")
    p.add_argument("--armature", default="", help="rig armature (default: the active object)")
    p.add_argument("--nla", action="store_true", help="push the action to a new NLA track")
    p.add_argument("--frame-start", type=int, default=1)
    p.add_argument("--action-name", default="")
    p.add_argument("--out", help="save to this .blend (default: overwrite --blend)")
    p.set_defaults(func=bake)

    p = sub.add_parser("export-bundle", help="write a rig (and its active action) in a .blend to a bundle")
    p.add_argument("--blend", required=True, help=".blend holding the rig")
    p.add_argument("--out", required=True, help="bundle to write (.npz)")
    p.add_argument("--armature", default="", help="rig armature (default: the active object)")
    p.add_argument("--action", default="", help="action to read (default: the active one)")
    p.add_argument("--no-poses", action="store_true", help="write the model only")
    p.set_defaults(func=export_bundle)
