"""A new armature object from bone arrays (heads, tails, rolls in metres/radians, parents first)."""
import bpy
import numpy as np

from ..rig.builder import edit_mode, object_mode


def new_armature(context, name: str, names, parents, heads, tails, rolls, connect_tol: float = 1e-6):
    """An armature object linked to the scene's collection; a bone is connected to its parent when its
    head sits on the parent's tail (within ``connect_tol``)."""
    data = bpy.data.armatures.new(name)
    ob = bpy.data.objects.new(name, data)
    context.scene.collection.objects.link(ob)
    with object_mode(context), edit_mode(context, ob):
        made = []
        for b, bone in enumerate(names):
            eb = data.edit_bones.new(bone)
            eb.head, eb.tail, eb.roll = tuple(heads[b]), tuple(tails[b]), float(rolls[b])
            made.append(eb)
        for b, p in enumerate(parents):
            if p >= 0:
                made[b].parent = made[p]
                made[b].use_connect = bool(np.linalg.norm(np.subtract(heads[b], tails[p])) < connect_tol)
    return ob
