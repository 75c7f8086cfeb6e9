"""Shared input of the operators that read a model bundle (``.npz``): the file path property with its
file-browser filter, ``invoke`` opening the browser when no path was given, and the checked path."""
import bpy

from ..solver.errors import ArticulaInputError


class BundleFileInput:
    """Mixin (before ``bpy.types.Operator``): ``filepath`` of a bundle; the file browser on invoke."""

    filepath: bpy.props.StringProperty(name="Bundle", subtype='FILE_PATH')
    filter_glob: bpy.props.StringProperty(default="*.npz", options={'HIDDEN'})

    def invoke(self, context, event):
        if not self.filepath:
            context.window_manager.fileselect_add(self)
            return {'RUNNING_MODAL'}
        return self.execute(context)

    def bundle_path(self) -> str:
        """The absolute path of ``filepath`` (``//`` = the .blend's folder); an empty one is refused."""
        if not self.filepath.strip():
            raise ArticulaInputError("no bundle file given (set filepath to a model bundle .npz)")
        return bpy.path.abspath(self.filepath)
