"""``articula.retarget`` and the mapping-list operators of the Retarget panel: copy the source's active
action onto the target as a new action, by bone roles (automatic, the panel's list, or a JSON mapping)
or through shared mesh topology."""
import contextlib

import bpy
from bpy_extras.io_utils import ExportHelper, ImportHelper

from ..addon.linked import check_editable
from ..addon.retarget import mapping_list, skeleton
from ..addon.retarget.armatures import find_armature
from ..solver.errors import ArticulaInputError
from ..solver.retarget.mapping import Mapping
from ..solver.retarget.solve import RetargetOptions

MAPPINGS = (
    ('AUTO', "Automatic", "Find the roles by rig presets, then by the skeletons' shape"),
    ('LIST', "Panel List", "Use the role list shown in the Retarget panel"),
    ('FILE', "Mapping File", "Use a saved JSON mapping (Mapping File)"),
    ('TOPOLOGY', "Shared Topology", "Fit the target's poses to the source's posed mesh, vertex for vertex "
                                    "(two Articula rigs whose meshes share their topology)"),
)


def _pair(context, source: str, target: str):
    """Source and target armature objects: named, else the panel's, else selected + active."""
    state = context.scene.articula_retarget
    if not source and state.source is not None:
        source = state.source.name
    if not target and state.target is not None:
        target = state.target.name
    if not (source and target):
        active = context.active_object
        others = [o for o in context.selected_objects if o != active and o.type == 'ARMATURE']
        if active is not None and others:
            source, target = source or others[0].name, target or active.name
    return find_armature(source, "source"), find_armature(target, "target")


@contextlib.contextmanager
def _cursor_progress(context):
    """``progress(fraction, text)`` shown as the window's progress cursor (no window: nothing shown)."""
    wm = context.window_manager if context.window is not None else None
    if wm is not None:
        wm.progress_begin(0, 1000)
    try:
        yield (lambda fraction, text: wm.progress_update(int(1000 * fraction))) if wm else None
    finally:
        if wm is not None:
            wm.progress_end()


class ARTICULA_OT_retarget(bpy.types.Operator):
    """Copy the source armature's active action onto the target as a new action (limb directions,
    twist and root motion retargeted; nothing is overwritten)"""
    bl_idname = "articula.retarget"
    bl_label = "Retarget Action"
    bl_options = {'REGISTER', 'UNDO'}

    source: bpy.props.StringProperty(name="Source", description="Armature with the motion (default: the panel's "
                                                                "source, or the selected armature)")
    target: bpy.props.StringProperty(name="Target", description="Armature that receives a new action (default: "
                                                                "the panel's target, or the active armature)")
    mapping: bpy.props.EnumProperty(name="Mapping", items=MAPPINGS, default='AUTO')
    mapping_file: bpy.props.StringProperty(name="Mapping File", subtype='FILE_PATH',
                                           description="JSON mapping saved from the panel (Mapping: File)")
    root_motion: bpy.props.BoolProperty(name="Root Motion", default=True,
                                        description="Move the hips as the source's, scaled by the leg-length ratio")
    in_place: bpy.props.BoolProperty(name="In Place", default=False,
                                     description="Remove the travel, keep the sway and the hip bob")
    foot_cleanup: bpy.props.BoolProperty(name="Plant Feet", default=False,
                                         description="Feet that rest on the ground in the source stay planted")

    def _mapping(self, context):
        if self.mapping == 'LIST':
            state = context.scene.articula_retarget
            if not len(state.rows):
                raise ArticulaInputError("the Retarget panel's role list is empty: press Find Mapping first")
            return mapping_list.to_mapping(state)
        if self.mapping == 'FILE':
            path = bpy.path.abspath(self.mapping_file)
            try:
                with open(path, encoding="utf-8") as fh:
                    return Mapping.from_json(fh.read(), path)
            except OSError as exc:
                raise ArticulaInputError(f"cannot read the mapping file {path!r}: {exc.strerror}") from None
        return None

    def execute(self, context):
        try:
            source, target = _pair(context, self.source, self.target)
            check_editable(target, "target")
            if self.mapping == 'TOPOLOGY':
                from ..addon.retarget.topology import retarget_topology_rigs
                action, report = retarget_topology_rigs(context, source, target)
                self.report({'INFO'}, f"Retargeted through shared topology into action {action.name!r}")
                return {'FINISHED'}
            options = RetargetOptions(self.root_motion, self.in_place, self.foot_cleanup)
            with _cursor_progress(context) as progress:
                action, report = skeleton.retarget(context, source, target, self._mapping(context), options,
                                                   progress=progress)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, skeleton.summary(report))
        return {'FINISHED'}


class ARTICULA_OT_retarget_find_mapping(bpy.types.Operator):
    """Fill the role list from rig presets and the skeletons' shape"""
    bl_idname = "articula.retarget_find_mapping"
    bl_label = "Find Mapping"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        state = context.scene.articula_retarget
        try:
            source, target = _pair(context, "", "")
            mapping, src, tgt = skeleton.auto_mapping(source, target)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        how = f"source: {src.preset or 'shape'}, target: {tgt.preset or 'shape'}"
        mapping_list.fill(state, mapping, how)
        state.source, state.target = source, target
        missing = mapping.missing()
        self.report({'WARNING'} if missing else {'INFO'},
                    f"{len(mapping.pairs())} roles mapped ({how})"
                    + (f"; not found: {', '.join(missing)}" if missing else ""))
        return {'FINISHED'}


class ARTICULA_OT_retarget_save_mapping(bpy.types.Operator, ExportHelper):
    """Save the role list as a JSON mapping"""
    bl_idname = "articula.retarget_save_mapping"
    bl_label = "Save Mapping"
    filename_ext = ".json"
    filter_glob: bpy.props.StringProperty(default="*.json", options={'HIDDEN'})

    def execute(self, context):
        state = context.scene.articula_retarget
        if not len(state.rows):
            self.report({'ERROR'}, "the role list is empty: press Find Mapping first")
            return {'CANCELLED'}
        try:
            with open(self.filepath, "w", encoding="utf-8") as fh:
                fh.write(mapping_list.to_mapping(state).to_json())
        except OSError as exc:
            self.report({'ERROR'}, f"cannot write {self.filepath!r}: {exc.strerror}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"Saved {len(state.rows)} roles to {self.filepath}")
        return {'FINISHED'}


class ARTICULA_OT_retarget_load_mapping(bpy.types.Operator, ImportHelper):
    """Load a JSON mapping into the role list"""
    bl_idname = "articula.retarget_load_mapping"
    bl_label = "Load Mapping"
    bl_options = {'REGISTER', 'UNDO'}
    filename_ext = ".json"
    filter_glob: bpy.props.StringProperty(default="*.json", options={'HIDDEN'})

    def execute(self, context):
        try:
            with open(self.filepath, encoding="utf-8") as fh:
                mapping = Mapping.from_json(fh.read(), self.filepath)
        except OSError as exc:
            self.report({'ERROR'}, f"cannot read {self.filepath!r}: {exc.strerror}")
            return {'CANCELLED'}
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        mapping_list.fill(context.scene.articula_retarget, mapping, bpy.path.basename(self.filepath))
        self.report({'INFO'}, f"Loaded {len(mapping.rows)} roles")
        return {'FINISHED'}


classes = (ARTICULA_OT_retarget, ARTICULA_OT_retarget_find_mapping, ARTICULA_OT_retarget_save_mapping,
           ARTICULA_OT_retarget_load_mapping)
