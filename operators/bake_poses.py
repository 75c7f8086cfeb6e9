"""``articula.bake_poses``: bake the poses of a bundle onto an existing rig as a new action."""
import bpy

from ..addon.rig import bundle_io as rig_io
from ..addon.jobs import JobOperator
from .bundle_file import BundleFileInput


class ARTICULA_OT_bake_poses(BundleFileInput, JobOperator, bpy.types.Operator):
    """Bake the poses of a bundle (.npz) as a new action on an Articula rig"""
    bl_idname = "articula.bake_poses"
    bl_label = "Bake Poses to Action"
    bl_options = {'REGISTER', 'UNDO'}

    armature: bpy.props.StringProperty(name="Armature", description="Rig armature (default: the active rig)")
    nla: bpy.props.BoolProperty(name="Push to NLA", default=False,
                                description="Put the action on a new NLA track instead of making it active")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1)
    action_name: bpy.props.StringProperty(name="Action Name", description="Default: '<bundle> poses'")

    job_label = "Bake poses"

    def prepare(self, context):
        path = self.bundle_path()
        return lambda progress: path

    def finish(self, context, path):
        action = rig_io.bake_bundle(context, path, self.armature, self.nla, self.frame_start, self.action_name,
                                    warn=lambda text: self.report({'WARNING'}, text))
        where = "an NLA track" if self.nla else "the active action"
        self.report({'INFO'}, f"Baked {action.name!r} as {where}")


classes = (ARTICULA_OT_bake_poses,)
