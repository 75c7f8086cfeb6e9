"""``articula.export_lbs``: convert an Articula rig into a plain linear-blend rig with twist segment
bones (for FBX/glTF and game engines), at most Max Influences bones per vertex, and report how far it
deviates from the exact rig (and the unlimited version)."""
import bpy

from ..addon.rig import linear_blend as lbs_rig
from ..addon.rig import reader as rig_reader
from ..addon.jobs import scene_guard
from ..solver.errors import ArticulaInputError
from ..solver.rig import linear_blend as lbs


class ARTICULA_OT_export_lbs(bpy.types.Operator):
    """Convert an Articula rig into a plain linear-blend rig (twist segment bones) and report the
    maximum deviation from the exact rig in millimetres"""
    bl_idname = "articula.export_lbs"
    bl_label = "Convert to Linear-Blend Rig"
    bl_options = {'REGISTER', 'UNDO'}

    armature: bpy.props.StringProperty(name="Armature", description="Rig armature (default: the active rig)")
    segments: bpy.props.IntProperty(name="Twist Segments", default=4, min=1, max=lbs.MAX_SEGMENTS,
                                    description="Twist segment bones per joint")
    max_influences: bpy.props.IntProperty(
        name="Max Influences", default=4, min=0, max=lbs.MAX_INFLUENCES,
        description="Bones per vertex at most: 4 for glTF (its exporter drops the rest), 8 for FBX, "
                    "0 = unlimited. Weights of vertices with more are refitted to the exact rig, not truncated")

    def execute(self, context):
        try:
            arm = rig_reader.find_armature(self.armature, context)
            with scene_guard():
                rig = lbs_rig.build_lbs_rig(context, arm, self.segments, self.max_influences)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, lbs_rig.summary(rig))
        return {'FINISHED'}


classes = (ARTICULA_OT_export_lbs,)
