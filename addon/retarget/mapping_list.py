"""The Retarget panel's state, saved with the .blend (``Scene.articula_retarget``): source, target, the
editable role list (one row per role: source bone, target bone) and the options; plus the list's
UI drawing and the conversion to and from :class:`solver.retarget.mapping.Mapping`."""
import bpy

from ...solver.retarget.mapping import Mapping
from ...solver.roles import ROLES


def _is_armature(self, ob):
    return ob.type == 'ARMATURE'


class ArticulaRoleRow(bpy.types.PropertyGroup):
    role: bpy.props.StringProperty(name="Role", description="What the bones do (upper_arm.L = left upper arm)")
    source_bone: bpy.props.StringProperty(name="Source Bone", description="The source armature's bone")
    target_bone: bpy.props.StringProperty(name="Target Bone", description="The target armature's bone")


class ArticulaRetargetState(bpy.types.PropertyGroup):
    source: bpy.props.PointerProperty(name="Source", type=bpy.types.Object, poll=_is_armature,
                                      description="Armature whose active action is retargeted")
    target: bpy.props.PointerProperty(name="Target", type=bpy.types.Object, poll=_is_armature,
                                      description="Armature that receives a new action")
    rows: bpy.props.CollectionProperty(type=ArticulaRoleRow)
    active_row: bpy.props.IntProperty(name="Active Row", default=0)
    found: bpy.props.StringProperty(name="Found", description="How the list was made")


class ARTICULA_UL_roles(bpy.types.UIList):
    """One row per role: the role, then searchable source and target bone fields."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index=0):
        state = data
        row = layout.row(align=True)
        row.label(text=item.role)
        if state.source is not None and state.source.type == 'ARMATURE':
            row.prop_search(item, "source_bone", state.source.data, "bones", text="")
        else:
            row.prop(item, "source_bone", text="")
        if state.target is not None and state.target.type == 'ARMATURE':
            row.prop_search(item, "target_bone", state.target.data, "bones", text="")
        else:
            row.prop(item, "target_bone", text="")


def to_mapping(state) -> Mapping:
    """The list as a :class:`Mapping` (rows in role order)."""
    order = {r: i for i, r in enumerate(ROLES)}
    rows = sorted(((r.role, r.source_bone, r.target_bone) for r in state.rows if r.role in order),
                  key=lambda row: order[row[0]])
    return Mapping(rows)


def fill(state, mapping: Mapping, found: str = "") -> None:
    """Replace the list with ``mapping``'s rows."""
    state.rows.clear()
    for role, source, target in mapping.rows:
        row = state.rows.add()
        row.role, row.source_bone, row.target_bone = role, source, target
    state.active_row = 0
    state.found = found


classes = (ArticulaRoleRow, ArticulaRetargetState, ARTICULA_UL_roles)


def register_extra():
    bpy.types.Scene.articula_retarget = bpy.props.PointerProperty(type=ArticulaRetargetState)


def unregister_extra():
    del bpy.types.Scene.articula_retarget
