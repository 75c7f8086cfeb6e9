"""Shared input of the operators that read a model bundle (``.npz``): the file path property with its
file-browser filter, and ``invoke`` opening the browser when no path was given."""
import bpy


class BundleFileInput:
    """Mixin (before ``bpy.types.Operator``): ``filepath`` of a bundle; the file browser on invoke."""

    filepath: bpy.props.StringProperty(name="Bundle", subtype='FILE_PATH')
    filter_glob: bpy.props.StringProperty(default="*.npz", options={'HIDDEN'})

    def invoke(self, context, event):
        if not self.filepath:
            context.window_manager.fileselect_add(self)
            return {'RUNNING_MODAL'}
        return self.execute(context)
