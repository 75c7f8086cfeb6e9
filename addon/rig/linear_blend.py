"""Build the plain linear-blend version of an Articula rig in the scene (the Blender half of
``solver.rig.linear_blend``): an armature with the control bones, swing helpers and twist segment
bones, and a copy of the rig mesh with one plain Armature modifier, sharing the rig's active action.
At most ``max_influences`` bones per vertex (glTF keeps 4): the solver fits the limited weights.

Twist segment bones are driven like the twist bones of the hybrid rig (SWING_TWIST_Y, local space) with
the simple expression ``twist * k / n``, which Blender evaluates without Python.
"""
from dataclasses import dataclass

import bpy
from mathutils import Matrix

from ...solver.rig import linear_blend as lbs
from ...solver.rig import names as rig_names
from .. import compat
from ..scene.mesh_io import write_vertex_groups
from . import builder as rig_builder
from . import reader as rig_reader

MAX_DEVIATION_PROP = "articula_lbs_max_mm"
UNLIMITED_DEVIATION_PROP = "articula_lbs_unlimited_max_mm"
MAX_INFLUENCES_PROP = "articula_lbs_max_influences"


@dataclass
class LbsRig:
    armature: bpy.types.Object
    mesh: bpy.types.Object
    max_mm: float          # max |LBS - hybrid| over the measured poses, millimetres (the rig built)
    mean_mm: float
    poses_measured: int
    poses_source: str      # 'ACTION' or 'RANDOM'
    max_influences: int    # bones per vertex at most (0 = unlimited)
    unlimited_max_mm: float   # the same measures for the unlimited weights
    unlimited_mean_mm: float
    vertices_limited: int  # vertices whose weights were refitted


def _edit_segments(arm_data, layout):
    helpers = arm_data.collections[rig_names.HELPERS_COLLECTION]
    ebs = arm_data.edit_bones
    for name, kind, c, k in layout:
        if kind not in ('S', 'N'):
            continue
        ref = ebs[layout[c][0]]                                   # control bone c (same rest)
        eb = ebs.new(name)
        eb.head, eb.tail, eb.roll = ref.head, ref.tail, ref.roll
        eb.parent = ebs[rig_names.swing(ref.name)] if kind == 'S' else ref.parent
        eb.use_deform = True
        eb.hide = True
        helpers.assign(eb)


def _drive_segments(arm, layout, segments):
    for name, kind, c, k in layout:
        if kind not in ('S', 'N'):
            continue
        pb = arm.pose.bones[name]
        pb.rotation_mode = 'XYZ'
        rig_builder.lock(pb)
        driver = pb.driver_add("rotation_euler", 1).driver
        driver.type = 'SCRIPTED'
        driver.expression = f"twist * {k} / {segments}"
        var = driver.variables.new()
        var.name, var.type = "twist", 'TRANSFORMS'
        t = var.targets[0]
        t.id, t.bone_target = arm, layout[c][0]
        t.transform_type, t.rotation_mode, t.transform_space = 'ROT_Y', 'SWING_TWIST_Y', 'LOCAL_SPACE'


def _measure_poses(arm, model):
    """The rig's action poses, or seeded random poses (``lbs.sample_poses``: swings up to 110°, twists
    up to ±90°) when it has none."""
    if arm.animation_data is not None and arm.animation_data.action is not None:
        return rig_reader.read_poses(arm), 'ACTION'
    return lbs.sample_poses(model.skeleton.num_bones, lbs.MEASURE_SEED), 'RANDOM'


def lbs_rig_weights(model, segments: int, max_influences: int):
    """The weights the LBS rig gets: ``(layout, W (V, J))``, at most ``max_influences`` per vertex
    (0 = unlimited) fitted to the seeded poses ``lbs.sample_poses(.., lbs.FIT_SEED)``."""
    fit = lbs.sample_poses(model.skeleton.num_bones, lbs.FIT_SEED)
    return lbs.limited_weights(model, segments, max_influences, fit)


def build_lbs_rig(context, arm, segments: int = 4, max_influences: int = 4) -> LbsRig:
    """Create the LBS version of the rig whose main armature is ``arm`` with at most ``max_influences``
    bones per vertex (0 = unlimited); returns :class:`LbsRig` with both deviations."""
    model = rig_reader.read_model(arm)
    layout, full = lbs.lbs_weights(model, segments)          # validates names and segments
    layout, weights = lbs_rig_weights(model, segments, max_influences)
    poses, source = _measure_poses(arm, model)
    full_worst, full_mean = lbs.deviation(model, poses, segments, weights=full)
    limited = int(((full > 0).sum(axis=1) > max_influences).sum()) if max_influences > 0 else 0
    worst, mean = lbs.deviation(model, poses, segments, weights=weights) if limited else (full_worst, full_mean)
    src_mesh = rig_reader.find_mesh(arm)
    sk = model.skeleton
    with rig_builder.object_mode(context):
        lbs_arm = bpy.data.objects.new(f"{arm.name}.lbs", bpy.data.armatures.new(f"{arm.name}.lbs"))
        mesh = bpy.data.objects.new(f"{src_mesh.name}.lbs", src_mesh.data.copy())
        coll = context.collection or context.scene.collection
        coll.objects.link(lbs_arm)
        coll.objects.link(mesh)
        for a in list(mesh.data.attributes):
            if a.name == rig_names.ANCHOR_ATTRIBUTE:
                mesh.data.attributes.remove(a)
        with rig_builder.edit_mode(context, lbs_arm):
            rig_builder.edit_main_bones(lbs_arm.data, sk)
            _edit_segments(lbs_arm.data, layout)
        rig_builder.pose_main(context.scene, lbs_arm, sk)
        _drive_segments(lbs_arm, layout, segments)
        mesh.vertex_groups.clear()
        write_vertex_groups(mesh, [name for name, *_ in layout], weights)
        mod = mesh.modifiers.new("Armature", 'ARMATURE')
        mod.object = lbs_arm
        mod.use_deform_preserve_volume = False
        mesh.parent = lbs_arm
        mesh.matrix_parent_inverse = Matrix.Identity(4)
        ad = arm.animation_data
        if ad is not None and ad.action is not None:
            compat.assign_action(lbs_arm, ad.action, getattr(ad, "action_slot", None))
        lbs_arm[MAX_DEVIATION_PROP] = float(worst.max() * 1000.0)
        lbs_arm[UNLIMITED_DEVIATION_PROP] = float(full_worst.max() * 1000.0)
        lbs_arm[MAX_INFLUENCES_PROP] = int(max_influences)
        context.view_layer.objects.active = lbs_arm
        lbs_arm.select_set(True)
    return LbsRig(lbs_arm, mesh, float(worst.max() * 1000.0), float(mean * 1000.0), len(poses), source,
                  int(max_influences), float(full_worst.max() * 1000.0), float(full_mean * 1000.0), limited)




def summary(rig: LbsRig) -> str:
    """One line for the operator's report and the batch command: bones, influences, both deviations."""
    what = "poses of the action" if rig.poses_source == 'ACTION' else "random poses (twists up to ±90°)"
    limit = (f"at most {rig.max_influences} influences per vertex ({rig.vertices_limited} vertices refitted)"
             if rig.max_influences > 0 else "unlimited influences per vertex")
    return (f"Linear-blend rig {rig.armature.name!r}: {len(rig.armature.data.bones)} bones, {limit}; "
            f"deviation from the exact rig max {rig.max_mm:.2f} mm, mean {rig.mean_mm:.3f} mm "
            f"(unlimited influences: max {rig.unlimited_max_mm:.2f} mm, mean {rig.unlimited_mean_mm:.3f} mm) "
            f"over {rig.poses_measured} {what}")
