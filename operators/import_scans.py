"""``articula.import_scans``: a sequence of scans -> a scan-sequence object that plays back per frame.

Sources (first match wins):
* ``files`` (names in ``directory``) or ``filepath``: OBJ/PLY/STL/OFF files, one frame each, or a
  folder of them (``directory``/``filepath`` naming a folder, no files selected), naturally sorted;
  one Alembic ``.abc``; or one MDD/PC2 point cache whose faces come from ``base_mesh`` (a mesh file)
  or ``source_object`` (else the active mesh object);
* ``source_object`` alone: a mesh object's shape keys (one frame per key, basis first) or its
  animation over ``source_frame_start..source_frame_end`` (0, 0: the scene's range).

``axis_forward`` / ``axis_up``: the files' axes (Blender's importer enum names; ``AUTO`` = the format's
convention, e.g. OBJ forward -Z, up Y).  The frames stay in file coordinates; the object matrix carries
the conversion (docs/scans.md, "Axes").
"""
import bpy
from bpy_extras.io_utils import ImportHelper

from ..addon.sequences import scan_sources
from ..addon.jobs import JobOperator
from ..solver.formats.axes import AUTO

AXIS_ITEMS = ((AUTO, "Format Default", "The file format's own convention, as Blender's importer for it: OBJ "
                                       "forward -Z, up Y; PLY, STL, OFF, MDD, PC2 as written (forward Y, up Z); "
                                       "Alembic converted by Blender's importer"),
              ('X', "X", ""), ('Y', "Y", ""), ('Z', "Z", ""),
              ('NEGATIVE_X', "-X", ""), ('NEGATIVE_Y', "-Y", ""), ('NEGATIVE_Z', "-Z", ""))


def axis_property(which: str):
    """The Forward/Up axis property of a file input (``which``: "Forward" or "Up")."""
    return bpy.props.EnumProperty(
        name=f"{which} Axis", items=AXIS_ITEMS, default=AUTO,
        description=f"The files' axis that becomes Blender's {'+Y (forward)' if which == 'Forward' else '+Z (up)'} "
                    f"(Format Default: the format's convention); the object matrix carries the conversion, the "
                    f"frames stay as written")


class ARTICULA_OT_import_scans(JobOperator, bpy.types.Operator, ImportHelper):
    """Import a sequence of scans (mesh files, a folder, Alembic, MDD/PC2, or a mesh object's shape keys
    or animation) as a scan-sequence object that plays back frame by frame"""
    bl_idname = "articula.import_scans"
    bl_label = "Import Scans"
    bl_options = {'REGISTER', 'UNDO'}
    job_label = "Import scans"

    filename_ext = ""
    # SKIP_SAVE (unlike ImportHelper's): a remembered path would make the next button press re-import
    # it without opening the file browser.
    filepath: bpy.props.StringProperty(subtype='FILE_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    filter_glob: bpy.props.StringProperty(default="*.obj;*.ply;*.stl;*.off;*.abc;*.mdd;*.pc2",
                                          options={'HIDDEN'})
    directory: bpy.props.StringProperty(subtype='DIR_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement,
                                        options={'HIDDEN', 'SKIP_SAVE'})
    source_object: bpy.props.StringProperty(
        name="Source Object", options={'SKIP_SAVE'},
        description="Mesh object to take frames from (shape keys or animation), or the base mesh of a point cache")
    base_mesh: bpy.props.StringProperty(
        name="Base Mesh", subtype='FILE_PATH', options={'SKIP_SAVE'},
        description="Mesh file giving the faces of an MDD/PC2 point cache")
    name: bpy.props.StringProperty(name="Name", options={'SKIP_SAVE'},
                                   description="Name of the new object (empty: after the folder or file)")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1,
                                       description="Scene frame that shows the first scan")
    require_registered: bpy.props.BoolProperty(
        name="Require Registered", default=False,
        description="Fail unless every frame has the same vertices and faces (needed to learn a rig)")
    object_frames: bpy.props.EnumProperty(
        name="Object Frames", default='AUTO',
        items=(('AUTO', "Auto", "Animation if the object is animated, else its shape keys"),
               ('SHAPE_KEYS', "Shape Keys", "One frame per shape key"),
               ('ANIMATION', "Animation", "The evaluated mesh at every frame of the range")))
    source_frame_start: bpy.props.IntProperty(name="Source Start", default=0,
                                              description="First frame of an animated source (0: scene start)")
    source_frame_end: bpy.props.IntProperty(name="Source End", default=0,
                                            description="Last frame of an animated source (0: scene end)")
    axis_forward: axis_property("Forward")
    axis_up: axis_property("Up")

    def _has_file_input(self):
        return bool(self.filepath or self.directory or any(f.name for f in self.files))

    def invoke(self, context, event):
        if self._has_file_input() or self.source_object:
            return JobOperator.invoke(self, context, event)
        self._browsing = True
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        if getattr(self, "_browsing", False) and not bpy.app.background:
            # Confirmed in the file browser: run as a modal job (progress + Esc) with the chosen input.
            self._browsing = False
            props = {p.identifier: getattr(self.properties, p.identifier)
                     for p in self.properties.bl_rna.properties if p.identifier not in ("rna_type", "files")}
            props["files"] = [{"name": f.name} for f in self.files]
            bpy.ops.articula.import_scans('INVOKE_DEFAULT', **props)
            return {'CANCELLED'}   # the job pushes its own undo step
        return JobOperator.execute(self, context)

    # -- job parts -----------------------------------------------------------------------------------
    def prepare(self, context):
        plan = scan_sources.plan_import(
            context, filepath=self.filepath, directory=self.directory, names=[f.name for f in self.files],
            source_object=self.source_object, base_mesh=self.base_mesh, name=self.name,
            require_registered=self.require_registered, object_frames=self.object_frames,
            source_range=(self.source_frame_start, self.source_frame_end),
            axes=(self.axis_forward, self.axis_up))
        return lambda progress: (plan, *plan.run(progress))

    def finish(self, context, result):
        plan, seq, path = result
        ob = plan.create_object(context, seq, path, self.frame_start)
        note = "registered" if seq.registered else f"unregistered ({seq.why_unregistered})"
        self.report({'INFO'}, f"{ob.name}: {len(seq)} frames of {len(seq.topology.vertices)} vertices, {note}")


classes = (ARTICULA_OT_import_scans,)
