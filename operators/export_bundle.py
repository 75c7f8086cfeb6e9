"""``articula.export_bundle`` and ``articula.read_action``: write an Articula rig (and the poses of an
action) back to a model bundle."""
import os

import bpy

from ..addon.rig import bundle_io as rig_io
from ..solver.errors import ArticulaInputError


class _ExportBase:
    bl_options = {'REGISTER', 'UNDO'}

    filepath: bpy.props.StringProperty(name="Bundle", subtype='FILE_PATH')
    filter_glob: bpy.props.StringProperty(default="*.npz", options={'HIDDEN'})
    armature: bpy.props.StringProperty(name="Armature", description="Rig armature (default: the active rig)")
    action: bpy.props.StringProperty(name="Action", description="Action to read (default: the active one)")

    poses_mode = 'ACTIVE'

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = "rig.npz"
            context.window_manager.fileselect_add(self)
            return {'RUNNING_MODAL'}
        return self.execute(context)

    def execute(self, context):
        path = bpy.path.abspath(self.filepath)
        if not path.endswith(".npz"):
            path += ".npz"
        try:
            model, poses = rig_io.export_bundle(path, self.armature, self.action, self.poses_mode, context)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        frames = f" and {len(poses)} poses" if poses is not None else ""
        self.report({'INFO'}, f"Wrote {os.path.basename(path)}: {model.num_vertices} vertices, "
                              f"{model.skeleton.num_bones} bones{frames}")
        return {'FINISHED'}


class ARTICULA_OT_export_bundle(_ExportBase, bpy.types.Operator):
    """Save an Articula rig (and its active action's poses, if any) as a model bundle (.npz)"""
    bl_idname = "articula.export_bundle"
    bl_label = "Save Rig as Bundle"


class ARTICULA_OT_read_action(_ExportBase, bpy.types.Operator):
    """Read an action of an Articula rig back to poses and save them with the rig as a bundle (.npz)"""
    bl_idname = "articula.read_action"
    bl_label = "Read Action to Poses"
    poses_mode = 'REQUIRED'


classes = (ARTICULA_OT_export_bundle, ARTICULA_OT_read_action)
