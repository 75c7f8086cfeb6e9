"""Read an Articula rig back from the scene into a :class:`solver.rig.model.Model` (the inverse of
:mod:`rig_builder`), plus its poses from an action (:mod:`actions`).

Where things come from: control bones are the bones carrying the ``articula_index`` property (bundle
order); heads, tails and frames are their rest ``head_local``/``tail_local``/``matrix_local`` (what
Blender deforms with); the rest mesh is the rig mesh's own vertex positions and its triangles; anchors
are the ``articula_anchor`` point attribute; twist weights are the ``TW-<c>`` groups and swing
weights the ``SW-<c>`` groups.  The rig mesh and twist armature are found through the Armature
modifiers that target the main armature, never by object name.
"""
import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.geometry.rotations import rotation_between
from ...solver.rig.model import Model, Poses, Skeleton
from . import actions
from ...solver.rig import names as rig_names
from ..scene.mesh_io import read_int_attribute, read_positions, read_triangles, read_vertex_groups


def find_armature(name: str = "", context=None) -> bpy.types.Object:
    """The main armature of a rig: the object ``name`` (a rig mesh or twist armature leads to its main
    armature), or the active object when ``name`` is empty."""
    context = context or bpy.context
    ob = bpy.data.objects.get(name) if name else context.active_object
    if ob is None:
        raise ArticulaInputError(f"no object named {name!r}" if name else "no active object")
    kind = ob.articula.kind
    if kind == 'RIG_MESH':
        mod = ob.modifiers.get(rig_names.SWING_MODIFIER)
        ob = mod.object if mod is not None else None
    elif kind == 'TWIST_ARMATURE':
        ob = ob.parent
    if ob is None or ob.type != 'ARMATURE' or ob.articula.kind != 'RIG_ARMATURE':
        raise ArticulaInputError(f"{name or 'the active object'} is not (part of) an Articula rig")
    return ob


def find_mesh(arm) -> bpy.types.Object:
    """The rig mesh whose main Armature modifier targets ``arm``."""
    for ob in bpy.data.objects:
        if ob.type == 'MESH' and ob.articula.kind == 'RIG_MESH':
            mod = ob.modifiers.get(rig_names.SWING_MODIFIER)
            if mod is not None and mod.object == arm:
                return ob
    raise ArticulaInputError(f"rig {arm.name!r} has no rig mesh (a mesh with an {rig_names.SWING_MODIFIER!r} "
                             "modifier targeting it)")


def control_names(arm) -> list:
    """Control-bone names of ``arm`` in bundle order."""
    indexed = [(b.get(rig_names.BONE_INDEX_PROP), b.name) for b in arm.data.bones]
    indexed = sorted((i, n) for i, n in indexed if i is not None)
    if not indexed or [i for i, _ in indexed] != list(range(len(indexed))):
        raise ArticulaInputError(f"rig {arm.name!r}: control bones are missing or their "
                                 f"{rig_names.BONE_INDEX_PROP!r} numbers are not 0..B-1")
    return [n for _, n in indexed]


def read_skeleton(arm) -> Skeleton:
    """The rest skeleton of the control bones of ``arm`` (armature space = world at identity)."""
    names = control_names(arm)
    bones = [arm.data.bones[n] for n in names]
    index = {n: i for i, n in enumerate(names)}
    parents = []
    for b in bones:
        p = b.parent.name if b.parent is not None else None
        parents.append(-1 if p is None else index.get(p, -2))
    if parents[0] != -1 or min(parents[1:], default=0) < 0:
        raise ArticulaInputError(f"rig {arm.name!r}: the control-bone hierarchy is broken")
    heads = np.array([b.head_local for b in bones], dtype=np.float64)
    tails = np.array([b.tail_local for b in bones], dtype=np.float64)
    frames = _nearest_rotations(np.array([np.array(b.matrix_local)[:3, :3] for b in bones], dtype=np.float64))
    return Skeleton(names, np.array(parents, dtype=np.int32), heads, tails, _along_bones(frames, heads, tails))


def _nearest_rotations(F):
    """The rotations nearest to ``F (B,3,3)`` (polar factor by SVD): Blender keeps bone matrices in float32,
    and for bones pointing close to −Y its roll computation leaves them orthonormal only to ~3e-6."""
    U, _, Vt = np.linalg.svd(F)
    return U @ Vt


def _along_bones(F, heads, tails):
    """``F (B,3,3)`` turned by the smallest rotation that puts each Y axis exactly on its bone's
    direction ``tail − head``: the float32 heads, tails and matrices Blender keeps agree only to a few
    1e-6 (measured 3.3e-6 on a learned rig), more than the model's frame tolerance."""
    y = tails - heads
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    return rotation_between(F[:, :, 1], y) @ F


def read_model(arm) -> Model:
    """The :class:`Model` of the rig whose main armature is ``arm``."""
    sk = read_skeleton(arm)
    mesh = find_mesh(arm)
    anchor = read_int_attribute(mesh.data, rig_names.ANCHOR_ATTRIBUTE)
    if anchor is None:
        raise ArticulaInputError(f"rig mesh {mesh.name!r} has no {rig_names.ANCHOR_ATTRIBUTE!r} attribute")
    joints = sk.names[1:]
    groups = [rig_names.twist(n) for n in joints] + [rig_names.swing(n) for n in joints]
    w = read_vertex_groups(mesh, groups)
    V, B = len(anchor), sk.num_bones
    twist = np.zeros((V, B), dtype=np.float32)
    swing = np.zeros((V, B), dtype=np.float32)
    twist[:, 1:] = w[:, :B - 1]
    swing[:, 1:] = w[:, B - 1:]
    model = Model(read_positions(mesh.data), read_triangles(mesh.data), sk, anchor, twist, swing)
    model.validate()
    return model


def read_poses(arm, action=None, frame_start=None, frame_end=None):
    """Poses of ``arm``'s control bones from ``action`` (default: its active action)."""
    return actions.read_action(arm, control_names(arm), action, frame_start, frame_end)


def read_current_pose(arm) -> Poses:
    """The pose (one frame) ``arm``'s control bones hold now (:func:`.actions.current_pose`)."""
    return actions.current_pose(arm, control_names(arm))
