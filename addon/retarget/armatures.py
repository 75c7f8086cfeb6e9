"""Blender armature objects as :class:`solver.retarget.armature.ArmatureRest`, and the checks a
retargeting source or target must pass before anything in the scene changes."""
import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.retarget.armature import ArmatureRest
from ..rig import reader as rig_reader


def find_armature(name: str, what: str) -> bpy.types.Object:
    """The armature object ``name`` (or the armature a mesh named ``name`` is rigged to)."""
    ob = bpy.data.objects.get(name) if name else None
    if ob is None:
        raise ArticulaInputError(f"no {what} object {name!r} in the file" if name else f"choose a {what} armature")
    if ob.articula.kind in ('RIG_MESH', 'TWIST_ARMATURE'):          # a part of an Articula rig: its controls
        return rig_reader.find_armature(ob.name)
    if ob.type == 'MESH':
        arm = ob.find_armature()
        if arm is None:
            raise ArticulaInputError(f"{what} {name!r} is a mesh without an armature modifier")
        ob = arm
    if ob.type != 'ARMATURE':
        raise ArticulaInputError(f"{what} {name!r} is a {ob.type.lower()}, not an armature")
    return ob


def check_scale(ob, what: str) -> None:
    """Refuse a non-uniformly scaled (or sheared) object: bone rotations cannot be expressed there."""
    M = np.array(ob.matrix_world, dtype=np.float64)[:3, :3]
    s = np.linalg.svd(M, compute_uv=False)
    if s.min() <= 1e-9 or s.max() / s.min() > 1.0 + 1e-4:
        raise ArticulaInputError(f"{what} {ob.name!r} is scaled non-uniformly {tuple(round(x, 4) for x in ob.scale)} "
                                 "(or sheared by a parent): apply its scale first (Object › Apply › Scale)")


def _parents_first(bones) -> list:
    order, seen = [], set()

    def visit(b):
        if b.name in seen:
            return
        if b.parent is not None:
            visit(b.parent)
        seen.add(b.name)
        order.append(b)
    for b in bones:
        visit(b)
    return order


def read_rest(ob) -> ArmatureRest:
    """The rest armature of object ``ob`` (bones ordered parents first); its world matrix as evaluated
    now (a script's pending transform edits are applied first, else ``matrix_world`` would be stale)."""
    bpy.context.view_layer.update()
    bones = _parents_first(ob.data.bones)
    if not bones:
        raise ArticulaInputError(f"armature {ob.name!r} has no bones")
    index = {b.name: i for i, b in enumerate(bones)}
    return ArmatureRest(
        ob.name, [b.name for b in bones],
        np.array([index[b.parent.name] if b.parent else -1 for b in bones]),
        np.array([np.array(b.matrix_local, dtype=np.float64) for b in bones]),
        np.array([np.array(b.tail_local, dtype=np.float64) for b in bones]),
        np.array([bool(b.use_connect) for b in bones]),
        np.array(ob.matrix_world, dtype=np.float64))


def constrained_bones(ob, bones=None) -> list:
    """Names of ``bones`` (default: all) whose pose bone has a constraint that is on (not muted, influence)."""
    return [pb.name for pb in ob.pose.bones if (bones is None or pb.name in bones)
            and any(not c.mute and c.influence > 0 for c in pb.constraints)]


def driven_bones(ob) -> list:
    """Names of the pose bones a driver of ``ob`` writes to."""
    ad = ob.animation_data
    out = set()
    for d in (ad.drivers if ad else []):
        path = d.data_path
        if path.startswith('pose.bones["'):
            out.add(path.split('"')[1])
    return sorted(out)
