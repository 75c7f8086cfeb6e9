"""Batch command ``export-lbs``: the plain linear-blend version of a rig in a .blend (as the operator
``articula.export_lbs`` makes it), saved as a .blend or exported as glTF / FBX.

    ./run export-lbs --blend rig.blend --out out/rig_lbs.glb                       (4 influences, glTF)
    ./run export-lbs --blend rig.blend --max-influences 8 --out out/rig_lbs.fbx
    ./run export-lbs --blend rig.blend --armature Body --segments 6 --max-influences 0 --out out/lbs.blend

``--out`` ``.blend`` saves the opened scene with the new rig added (``--blend`` itself is only written
when ``--out`` names it, with Blender's ``.blend1`` backup); ``.glb`` / ``.gltf`` / ``.fbx`` export only the
linear-blend armature and its mesh (with the rig's action, if any) and leave ``--blend`` untouched.
"""
import os

import bpy

from ...solver.errors import ArticulaInputError
from ...solver.rig import linear_blend as lbs
from .. import console
from ..jobs import scene_guard
from ..rig import linear_blend as lbs_rig
from ..rig import reader as rig_reader
from .common import finish, open_blend, save_blend_as

OUT_FORMATS = (".blend", ".glb", ".gltf", ".fbx")


def _check(args) -> str:
    """Validate the arguments before opening anything; returns the output's extension."""
    if not os.path.isfile(args.blend):
        raise ArticulaInputError(f"{args.blend}: no such .blend file")
    ext = os.path.splitext(args.out)[1].lower()
    if ext not in OUT_FORMATS:
        raise ArticulaInputError(f"--out {args.out}: unknown format {ext or '(no extension)'!r} "
                                 f"(known: {', '.join(OUT_FORMATS)})")
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        raise ArticulaInputError(f"--out {args.out}: folder {folder!r} does not exist")
    if not 1 <= args.segments <= lbs.MAX_SEGMENTS:
        raise ArticulaInputError(f"--segments must be 1..{lbs.MAX_SEGMENTS}, got {args.segments}")
    if not 0 <= args.max_influences <= lbs.MAX_INFLUENCES:
        raise ArticulaInputError(f"--max-influences must be 0..{lbs.MAX_INFLUENCES} (0 = unlimited), "
                                 f"got {args.max_influences}")
    return ext


def _export(rig, path: str, ext: str) -> None:
    """Write the LBS armature and mesh alone to a glTF / FBX file (without the glTF add-on's lines about
    its optional compression libraries, which read like a failure)."""
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob in (rig.armature, rig.mesh))
    animated = rig.armature.animation_data is not None and rig.armature.animation_data.action is not None
    if ext == ".fbx":
        bpy.ops.export_scene.fbx(filepath=path, use_selection=True, add_leaf_bones=False,
                                 bake_anim=animated)
        return
    with console.without_lines(console.GLTF_LIBRARIES):
        bpy.ops.export_scene.gltf(filepath=path, use_selection=True, export_animations=animated,
                                  export_format='GLB' if ext == ".glb" else 'GLTF_SEPARATE')


def export_lbs(args) -> int:
    ext = _check(args)
    open_blend(args.blend)
    arm = rig_reader.find_armature(args.armature, bpy.context)
    with scene_guard():
        rig = lbs_rig.build_lbs_rig(bpy.context, arm, args.segments, args.max_influences)
    if ext == ".blend":
        save_blend_as(args.out)
    else:
        _export(rig, os.path.abspath(args.out), ext)
    return finish(f"{lbs_rig.summary(rig)}; wrote {args.out}", scene=False)


def add_commands(sub):
    p = sub.add_parser("export-lbs", help="make the plain linear-blend version of a rig (glTF/FBX/.blend)")
    p.add_argument("--blend", required=True, help=".blend holding the Articula rig")
    p.add_argument("--armature", default="", help="rig armature (default: the active object)")
    p.add_argument("--segments", type=int, default=4, help="twist segment bones per joint (1..16, default 4)")
    p.add_argument("--max-influences", type=int, default=4,
                   help="bones per vertex at most, refitted to the exact rig: 4 for glTF (default), 8 for FBX, "
                        "0 = unlimited")
    p.add_argument("--out", required=True, help="file to write: .blend (scene with the new rig), .glb/.gltf, .fbx")
    p.set_defaults(func=export_lbs)
