"""Batch command ``retarget``: copy a motion onto a character in a .blend (as ``articula.retarget`` does)
and save the result as another .blend.

    ./run retarget --source motion.bvh --target character.blend --out out/retargeted.blend
    ./run retarget --source rig.blend --source-object Dancer --target character.blend --target-object Hero \\
        --mapping mapping.json --in-place --plant-feet --out out/hero_dance.blend

A BVH is imported with Blender's own importer and scaled so its legs are as long as the target's
(``--bvh-scale`` sets the importer's scale instead); an armature from another .blend is appended with its
action.  ``--target`` is never written; a command that fails saves nothing.
"""
import os

import bpy

from ...solver.errors import ArticulaInputError
from ...solver.formats.bvh import check_bvh
from ...solver.retarget.mapping import auto_roles
from ...solver.retarget.root_motion import leg_length
from ..linked import check_editable, overrides_of
from ..retarget.armatures import read_rest
from .common import call_operator, check_blend_output, finish, open_blend


def _check(args) -> None:
    for path, what in ((args.source, "--source"), (args.target, "--target")):
        if not os.path.isfile(path):
            raise ArticulaInputError(f"{what} {path}: no such file")
    if os.path.splitext(args.source)[1].lower() not in (".bvh", ".blend"):
        raise ArticulaInputError(f"--source {args.source}: give a .bvh motion or a .blend with an animated armature")
    if args.source.lower().endswith(".bvh"):
        check_bvh(args.source)
    if os.path.normpath(os.path.abspath(args.out)) == os.path.normpath(os.path.abspath(args.target)):
        raise ArticulaInputError(f"--out {args.out}: give another file than --target (it is never replaced)")
    if os.path.splitext(args.out)[1].lower() != ".blend":
        raise ArticulaInputError(f"--out {args.out}: must be a .blend file")
    if args.mapping not in ("auto", "topology") and not os.path.isfile(args.mapping):
        raise ArticulaInputError(f"--mapping {args.mapping}: no such file (or give 'auto' or 'topology')")
    check_blend_output(args.out)


def _armatures() -> list:
    """The file's armature objects, without the linked ones its library overrides stand for."""
    return [o for o in bpy.data.objects if o.type == 'ARMATURE' and not (o.library and overrides_of(o))]


def _pick(candidates, name: str, what: str, where: str):
    if not candidates:
        raise ArticulaInputError(f"{where} has no armature: give a .blend with the {what} character's armature")
    if name:
        match = [o for o in candidates if o.name == name]
        if not match:
            raise ArticulaInputError(f"{where} has no armature {name!r} (armatures: "
                                     f"{', '.join(o.name for o in candidates) or 'none'})")
        return match[0]
    animated = [o for o in candidates if o.animation_data and o.animation_data.action] if what == "source" \
        else [o for o in candidates if o.articula.kind != 'TWIST_ARMATURE']
    if len(animated) != 1:
        raise ArticulaInputError(f"{where} has {len(animated)} {'animated ' if what == 'source' else ''}armatures: "
                                 f"name the {what} with --{what}-object")
    return animated[0]


def _import_bvh(path: str, scale: float):
    before = set(bpy.data.objects)
    try:
        call_operator(bpy.ops.import_anim.bvh, filepath=os.path.abspath(path), global_scale=scale or 1.0)
    except ArticulaInputError as exc:
        reason = str(exc).strip().splitlines()[-1]
        raise ArticulaInputError(f"{path}: Blender's BVH importer could not read it ({reason})") from None
    new = [o for o in bpy.data.objects if o not in before and o.type == 'ARMATURE']
    if not new:
        raise ArticulaInputError(f"{path}: Blender's BVH importer made no armature")
    return new[0]


def _append(path: str, name: str):
    with bpy.data.libraries.load(os.path.abspath(path), link=False) as (src, dst):
        dst.objects = [n for n in src.objects if not name or n == name]
    candidates = [o for o in dst.objects if o is not None and o.type == 'ARMATURE']
    ob = _pick(candidates, name, "source", path)
    for other in dst.objects:
        if other is not None and other is not ob and other.users == 0:
            bpy.data.objects.remove(other)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _match_size(source, target) -> float:
    """Scale the imported BVH object so its legs are as long as the target's; returns the factor."""
    src, tgt = read_rest(source), read_rest(target)
    factor = leg_length(tgt, auto_roles(tgt).roles) / leg_length(src, auto_roles(src).roles)
    source.scale = (factor,) * 3
    bpy.context.view_layer.update()
    return factor


def retarget(args) -> int:
    _check(args)
    open_blend(args.target)
    target = _pick(_armatures(), args.target_object, "target", args.target)
    check_editable(target, "target")
    if args.source.lower().endswith(".bvh"):
        source = _import_bvh(args.source, args.bvh_scale)
        if not args.bvh_scale:
            _match_size(source, target)
    else:
        source = _append(args.source, args.source_object)
    mapping = {"auto": 'AUTO', "topology": 'TOPOLOGY'}.get(args.mapping, 'FILE')
    call_operator(bpy.ops.articula.retarget, source=source.name, target=target.name, mapping=mapping,
                  mapping_file=os.path.abspath(args.mapping) if mapping == 'FILE' else "",
                  root_motion=not args.no_root_motion, in_place=args.in_place, foot_cleanup=args.plant_feet)
    action = target.animation_data.action
    return finish(f"retargeted {source.name!r} onto {target.name!r}: action {action.name!r}, frames "
                  f"{action.frame_range[0]:.0f}-{action.frame_range[1]:.0f}", args.out)


def add_commands(sub):
    p = sub.add_parser("retarget", help="copy a motion (BVH or animated armature) onto a character as a new action")
    p.add_argument("--source", required=True, help="motion: a .bvh file, or a .blend with an animated armature")
    p.add_argument("--source-object", default="", help="armature in the --source .blend (default: the only animated one)")
    p.add_argument("--target", required=True, help=".blend with the character (never written)")
    p.add_argument("--target-object", default="", help="target armature (default: the file's only armature)")
    p.add_argument("--mapping", default="auto",
                   help="'auto' (default: rig presets, then the skeletons' shape), 'topology' (shared mesh), "
                        "or a JSON mapping saved from the Retarget panel")
    p.add_argument("--bvh-scale", type=float, default=0.0,
                   help="scale for Blender's BVH importer (default: match the target's leg length)")
    p.add_argument("--in-place", action="store_true", help="remove the travel, keep the sway and hip bob")
    p.add_argument("--plant-feet", action="store_true", help="keep feet planted while they rest in the source")
    p.add_argument("--no-root-motion", action="store_true", help="leave the hips where they are")
    p.add_argument("--out", required=True, help=".blend to save the result to")
    p.set_defaults(func=retarget)
