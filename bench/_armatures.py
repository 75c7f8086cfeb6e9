"""A new armature object from bone arrays, for the benchmarks, the tests and the docs' pictures that need
a character the add-on did not build (heads, tails in metres, rolls in radians, parents first).  Imported
as ``_armatures`` by benches (after ``_common``) and as ``articula.bench._armatures`` by tests and tools."""
import bpy
import numpy as np


def new_armature(context, name: str, names, parents, heads, tails, rolls, connect_tol: float = 1e-6):
    """An armature object linked to the scene's collection, left in object mode and deselected; a bone is
    connected to its parent when its head sits on the parent's tail (within ``connect_tol``)."""
    if context.mode != 'OBJECT' and context.view_layer.objects.active is not None:
        bpy.ops.object.mode_set(mode='OBJECT')
    data = bpy.data.armatures.new(name)
    ob = bpy.data.objects.new(name, data)
    context.scene.collection.objects.link(ob)
    for other in context.view_layer.objects:
        other.select_set(False)
    context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    try:
        made = []
        for b, bone in enumerate(names):
            eb = data.edit_bones.new(bone)
            eb.head, eb.tail, eb.roll = tuple(heads[b]), tuple(tails[b]), float(rolls[b])
            made.append(eb)
        for b, p in enumerate(parents):
            if p >= 0:
                made[b].parent = made[p]
                made[b].use_connect = bool(np.linalg.norm(np.subtract(heads[b], tails[p])) < connect_tol)
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')
        ob.select_set(False)
    return ob
