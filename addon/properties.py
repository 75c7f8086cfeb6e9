"""Data stored on Blender objects by Articula (``Object.articula``), so scenes survive save/reload.

Stored data carries ``data_version`` so later releases can migrate it.
"""
import bpy

from . import compat

DATA_VERSION = 1

OBJECT_KINDS = (
    ('NONE', "None", "Not an Articula object"),
    ('SCAN_SEQUENCE', "Scan Sequence", "A sequence of scans of one subject, one frame per scan"),
    ('POINT_CLOUD_SEQUENCE', "Point-Cloud Sequence", "Depth frames or point clouds, one frame per recording frame"),
    ('RIG_MESH', "Rig Mesh", "The skinned mesh of an Articula rig"),
    ('RIG_ARMATURE', "Rig Armature", "The main (control) armature of an Articula rig"),
    ('TWIST_ARMATURE', "Twist Armature", "The hidden twist armature of an Articula rig"),
)


class ArticulaObjectData(bpy.types.PropertyGroup):
    kind: bpy.props.EnumProperty(name="Kind", items=OBJECT_KINDS, default='NONE')
    data_version: bpy.props.IntProperty(name="Data Version", default=DATA_VERSION)
    registered: bpy.props.BoolProperty(
        name="Registered", default=False,
        description="All frames share one vertex count and topology (usable for rig learning)")
    source: bpy.props.StringProperty(name="Source", description="Where the data was imported from")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1)
    frame_count: bpy.props.IntProperty(name="Frames", default=0, min=0)
    cache_file: bpy.props.StringProperty(
        name="Cache File", subtype='FILE_PATH', options=compat.blend_relative_path_options(),
        description="Array cache holding every frame (relative to the .blend when saved)")


classes = (ArticulaObjectData,)


def register_extra():
    bpy.types.Object.articula = bpy.props.PointerProperty(type=ArticulaObjectData)


def unregister_extra():
    del bpy.types.Object.articula
