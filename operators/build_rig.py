"""``articula.build_rig``: build an Articula rig (mesh, control armature, twist armature) from a model
bundle, baking the bundle's poses (if any) as an action on frames 1..N."""
import bpy

from ..addon.rig import bundle_io as rig_io
from ..addon.rig import reader as rig_reader
from ..addon.jobs import JobOperator
from .bundle_file import BundleFileInput


class ARTICULA_OT_build_rig(BundleFileInput, JobOperator, bpy.types.Operator):
    """Build an Articula rig from a model bundle (.npz): mesh, control armature and twist armature"""
    bl_idname = "articula.build_rig"
    bl_label = "Build Rig from Bundle"
    bl_options = {'REGISTER', 'UNDO'}

    name: bpy.props.StringProperty(name="Name", description="Rig name (default: the bundle's file name)")
    bake: bpy.props.BoolProperty(name="Bake Poses", default=True,
                                 description="Bake the bundle's poses as a new action")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1)

    job_label = "Build rig"

    def prepare(self, context):
        path = self.bundle_path()
        bake = self.bake
        self._rig_name = self.name or rig_io.rig_name_for(path)
        return lambda progress: rig_io.load_for_build(path, bake)

    def finish(self, context, bundle):
        rig, action = rig_io.build_bundle(context, bundle, self._rig_name, self.bake, self.frame_start)
        for text in rig.warnings:
            self.report({'WARNING'}, text)
        sk_bones = len(rig_reader.control_names(rig.armature))
        baked = f", action {action.name!r} ({int(action.frame_range[1] - action.frame_range[0]) + 1} frames)" \
            if action is not None else ""
        self.report({'INFO'}, f"Built rig {rig.armature.name!r}: {len(rig.mesh.data.vertices)} vertices, "
                              f"{sk_bones} control bones{baked}")


classes = (ARTICULA_OT_build_rig,)
