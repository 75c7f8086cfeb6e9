"""The "Articula" tab in the 3D viewport's sidebar.  One panel per feature; each draws the buttons
of the operators that feature registered (operators missing from this build are skipped)."""
import re

import bpy

from .gaze.panel_state import SHOT_SETTINGS
from .sequences import playback


def _button(layout, idname: str, text: str, icon: str = 'NONE'):
    """Draw an operator button if the operator exists; return its properties (or None)."""
    cls_name = "ARTICULA_OT_" + idname.split(".", 1)[1]
    if not hasattr(bpy.types, cls_name):
        return None
    return layout.operator(idname, text=text, icon=icon)


class _ArticulaPanel:
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Articula"


class ARTICULA_PT_main(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Articula"

    def draw(self, context):
        ob = context.active_object
        col = self.layout.column(align=True)
        if ob is None or ob.articula.kind == 'NONE':
            col.label(text="Import scans or a depth recording to begin", icon='INFO')
            return
        data = ob.articula
        col.label(text=f"{ob.name}: {data.bl_rna.properties['kind'].enum_items[data.kind].name}")
        if data.frame_count:
            col.label(text=f"{data.frame_count} frames from frame {data.frame_start}")
        if data.kind == 'SCAN_SEQUENCE':
            col.label(text="Registered" if data.registered else "Unregistered (for tracking)")
        if data.kind in ('SCAN_SEQUENCE', 'POINT_CLOUD_SEQUENCE'):
            _draw_cache_problem(self.layout, ob)


def _draw_cache_problem(layout, ob) -> None:
    """A red box saying why a sequence object cannot play (its frame cache is missing or unusable) and
    what to do (:func:`playback.cache_problem`: put the named cache folder back, or import again)."""
    problem = playback.cache_problem(ob)
    if not problem:
        return
    box = layout.box()
    box.alert = True
    box.label(text="Cannot play this sequence", icon='ERROR')
    for line in _wrap(problem, 48):
        box.label(text=line)


def _wrap(text: str, width: int) -> list:
    """``text`` in lines of about ``width`` characters, broken after spaces and path separators."""
    lines, line = [], ""
    for part in re.split(r"(?<=[/ ])", text):
        if line and len(line) + len(part) > width:
            lines.append(line)
            line = ""
        line += part
    return [piece.strip() for piece in lines + [line] if piece.strip()]


class ARTICULA_PT_import(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Import"
    bl_parent_id = "ARTICULA_PT_main"

    def draw(self, context):
        col = self.layout.column(align=True)
        _button(col, "articula.import_scans", "Scans…", 'IMPORT')
        _button(col, "articula.import_depth", "Depth Recording…", 'OUTLINER_OB_POINTCLOUD')


class ARTICULA_PT_rig(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Rig"
    bl_parent_id = "ARTICULA_PT_main"

    def draw(self, context):
        col = self.layout.column(align=True)
        _button(col, "articula.learn_rig", "Learn Rig from Scans", 'ARMATURE_DATA')
        ob = context.active_object
        if ob is not None and ob.type == 'MESH' and "articula_error_scale_mm" in ob.data:
            col.label(text=f"Error heat map: blue 0 mm to red {ob.data['articula_error_scale_mm']:.1f} mm",
                      icon='COLOR')
        _button(col, "articula.build_rig", "Build Rig from Bundle…", 'OUTLINER_OB_ARMATURE')
        _button(col, "articula.export_bundle", "Save Rig as Bundle…", 'EXPORT')
        _button(col, "articula.export_lbs", "Convert to Linear-Blend Rig", 'MOD_ARMATURE')


class ARTICULA_PT_animate(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Animate"
    bl_parent_id = "ARTICULA_PT_main"

    def draw(self, context):
        col = self.layout.column(align=True)
        _button(col, "articula.bake_poses", "Bake Poses to Action…", 'ACTION')
        _button(col, "articula.read_action", "Read Action to Poses…", 'FILE_TICK')
        _button(col, "articula.bind_scan", "Bind Scan to Rig", 'MOD_MESHDEFORM')


class ARTICULA_PT_track(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Track"
    bl_parent_id = "ARTICULA_PT_main"

    def draw(self, context):
        col = self.layout.column(align=True)
        col.label(text="Select a rig and a scan or point sequence,")
        col.label(text="or a depth recording (no rig: template body)")
        _button(col, "articula.track", "Track Captures…", 'CON_ARMATURE')


class ARTICULA_PT_retarget(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Retarget"
    bl_parent_id = "ARTICULA_PT_main"

    def draw(self, context):
        state = getattr(context.scene, "articula_retarget", None)
        if state is None:
            return
        col = self.layout.column(align=True)
        col.prop(state, "source")
        col.prop(state, "target")
        row = col.row(align=True)
        _button(row, "articula.retarget_find_mapping", "Find Mapping", 'VIEWZOOM')
        _button(row, "articula.retarget_load_mapping", "", 'FILEBROWSER')
        _button(row, "articula.retarget_save_mapping", "", 'FILE_TICK')
        if len(state.rows):
            if state.found:
                col.label(text=state.found, icon='INFO')
            col.template_list("ARTICULA_UL_roles", "", state, "rows", state, "active_row", rows=6)
        op = _button(col, "articula.retarget", "Retarget Action", 'ACTION_TWEAK')
        if op is not None:
            op.mapping = 'LIST' if len(state.rows) else 'AUTO'
        op = _button(col, "articula.retarget", "Retarget by Shared Mesh", 'MOD_DATA_TRANSFER')
        if op is not None:
            op.mapping = 'TOPOLOGY'


class ARTICULA_PT_gaze(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Gaze"
    bl_parent_id = "ARTICULA_PT_main"

    def draw(self, context):
        state = getattr(context.scene, "articula_gaze", None)
        if state is None:
            return
        col = self.layout.column(align=True)
        col.label(text="Active armature looks at:")
        col.prop(state, "target")
        row = col.row(align=True)
        row.prop(state, "frame_start")
        row.prop(state, "frame_end")
        col.prop(state, "fade_frames")
        col.prop(state, "shares")
        ob = context.active_object
        for name in ("chest", "neck", "head"):
            if ob is not None and ob.type == 'ARMATURE':
                col.prop_search(state, name, ob.data, "bones")
            else:
                col.prop(state, name)
        col.prop(state, "facing")
        op = _button(col, "articula.gaze", "Look at Target", 'HIDE_OFF')
        if op is not None:
            for key in SHOT_SETTINGS + ("frame_start", "frame_end"):
                setattr(op, key, getattr(state, key))
            op.target = state.target.name if state.target else ""


# Icons of a farm task's status on the Manager (others: none).
_TASK_ICONS = {"completed": 'CHECKMARK', "active": 'PLAY', "queued": 'TIME', "failed": 'ERROR',
               "canceled": 'CANCEL'}


class ARTICULA_PT_farm(_ArticulaPanel, bpy.types.Panel):
    bl_label = "Farm"
    bl_parent_id = "ARTICULA_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        state = getattr(context.scene, "articula_farm", None)
        if state is None:
            return
        col = self.layout.column(align=True)
        for name in ("manager_url", "model", "input_dir", "kind") + (("camera",) if state.kind == 'DEPTH' else ()):
            col.prop(state, name)
        col.prop(state, "out")
        col.prop(state, "blend")
        row = col.row(align=True)
        row.prop(state, "chunk")
        row.prop(state, "overlap")
        col.prop(state, "retries")
        row = col.row(align=True)
        _button(row, "articula.farm_submit", "Submit", 'EXPORT')
        _button(row, "articula.farm_cancel", "Cancel", 'CANCEL')      # greyed out unless a job is followed
        if state.job_id or state.status_text:
            _draw_farm_status(self.layout.box(), state)


def _draw_farm_status(box, state) -> None:
    """The followed job: its id, status line, share of tasks done and one row per chunk (and merge)."""
    if state.job_id:
        box.label(text=f"Job {state.job_id}", icon='NETWORK_DRIVE')
    for line in _wrap(state.status_text, 48):
        box.label(text=line)
    if state.job_id:
        box.progress(factor=state.progress, type='BAR', text=f"{100 * state.progress:.0f}%")
    col = box.column(align=True)
    for item in state.chunks:
        row = col.row(align=True)
        row.label(text=item.name)
        row.label(text=item.status, icon=_TASK_ICONS.get(item.status, 'NONE'))


classes = (ARTICULA_PT_main, ARTICULA_PT_import, ARTICULA_PT_rig, ARTICULA_PT_animate, ARTICULA_PT_track,
           ARTICULA_PT_retarget, ARTICULA_PT_gaze, ARTICULA_PT_farm)
