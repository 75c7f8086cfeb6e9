"""``articula.bind_scan``: make a detailed static scan follow an Articula rig (a Surface Deform modifier on
the scan, bound to the rig mesh in the current or the rest pose; see ``addon/retarget/scan_binding.py``)."""
import bpy

from ..addon.retarget import scan_binding
from ..solver.errors import ArticulaInputError


class ARTICULA_OT_bind_scan(bpy.types.Operator):
    """Bind a high-resolution scan to the fitted Articula rig so that it follows every pose (Blender's
    Surface Deform, bound where scan and rig coincide). Binding again replaces the previous binding"""
    bl_idname = "articula.bind_scan"
    bl_label = "Bind Scan to Rig"
    bl_options = {'REGISTER', 'UNDO'}

    scan: bpy.props.StringProperty(name="Scan", description="Scan mesh object (default: the active mesh)")
    rig: bpy.props.StringProperty(name="Rig", description="Articula rig: its armature or rig mesh "
                                                          "(default: the selected rig)")
    bind_pose: bpy.props.EnumProperty(
        name="Bind Pose", items=scan_binding.BIND_POSES, default='CURRENT',
        description="The rig's pose in which the scan and the rig mesh coincide")

    def execute(self, context):
        try:
            scan = scan_binding.find_scan(self.scan, context)
            arm = scan_binding.find_rig(self.rig, context)
            binding = scan_binding.bind_scan(context, scan, arm, self.bind_pose)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        for warning in binding.warnings:
            self.report({'WARNING'}, warning)
        self.report({'INFO'}, scan_binding.summary(binding))
        return {'FINISHED'}


classes = (ARTICULA_OT_bind_scan,)
