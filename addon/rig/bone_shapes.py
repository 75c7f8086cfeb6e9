"""Custom shapes ("widgets") for the control bones: small wire meshes generated on demand and kept in
a hidden collection, shared by every rig of the file.

Shapes are in bone space and scaled by the bone length: a circle around the bone's Y axis (limbs,
spine) and a larger square for the root.  Each widget object is marked with the custom property
``articula_widget`` = its kind, so it is found again even after a rename.
"""
import math

import bpy
import numpy as np

from ...solver.rig import names as rig_names

WIDGET_PROP = "articula_widget"


def _circle(n=24, radius=0.25, y=0.5):
    t = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    verts = np.stack([radius * np.cos(t), np.full(n, y), radius * np.sin(t)], axis=1)
    edges = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    return verts, edges


def _square(half=0.6):
    verts = np.array([(-half, 0, -half), (half, 0, -half), (half, 0, half), (-half, 0, half)], float)
    return verts, np.array([(0, 1), (1, 2), (2, 3), (3, 0)])


SHAPES = {"CIRCLE": _circle, "ROOT": _square}


def _widget_collection(scene) -> bpy.types.Collection:
    coll = bpy.data.collections.get(rig_names.WIDGETS_COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(rig_names.WIDGETS_COLLECTION)
        coll.hide_viewport = True
        coll.hide_render = True
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    return coll


def widget(scene, kind: str) -> bpy.types.Object:
    """The shared widget object of ``kind`` ('CIRCLE' or 'ROOT'), created when missing."""
    for ob in bpy.data.objects:
        if ob.get(WIDGET_PROP) == kind and ob.library is None:
            return ob
    verts, edges = SHAPES[kind]()
    me = bpy.data.meshes.new(f"WGT-articula-{kind.lower()}")
    me.from_pydata(verts.tolist(), edges.tolist(), [])
    ob = bpy.data.objects.new(me.name, me)
    ob[WIDGET_PROP] = kind
    _widget_collection(scene).objects.link(ob)
    return ob
