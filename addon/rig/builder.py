"""Build an Articula rig in the scene from a :class:`solver.rig.model.Model` (docs/RIG.md, "Why the rig
deforms exactly as the solver's hybrid skin").

The rig is three objects, all at the identity transform (bundle coordinates are Blender world
coordinates unchanged); the mesh and the twist armature are parented to the main armature so the
whole rig moves with it:

* main armature (``kind`` RIG_ARMATURE): one control bone per part (bundle names, rotation mode
  QUATERNION, collection "Controls", custom shapes and side colours) and, for every joint c > 0, a swing
  helper ``SW-<c>``: child of the parent part's control bone, rest equal to control c, with a Damped
  Track (Y) to the tail of control c, i.e. exactly the shortest-arc swing of c about its rest head
  (collection "Helpers", hidden, locked);
* twist armature (``kind`` TWIST_ARMATURE, hidden): ``TW-<c>`` at the rest of c, unparented, whose Y
  Euler rotation is driven by the SWING_TWIST_Y twist of control c (local space), plus a static
  ``NEUTRAL`` bone;
* mesh (``kind`` RIG_MESH): vertex groups ``TW-*``/``NEUTRAL`` (twist weights and remainder), ``SW-*``
  (swing weights) and the anchor part's control bone (swing remainder), the anchor bone index as the
  INT point attribute ``articula_anchor``, and two Armature modifiers in sequence: twist armature with
  Preserve Volume (dual quaternions), then the main armature (linear).

Staged like Rigify: create objects, one edit-mode pass per armature for bones, then one pose pass for
constraints, drivers and display.  :func:`check_model` validates everything first, so bad input raises
:class:`ArticulaInputError` before anything is created.
"""
from contextlib import contextmanager
from dataclasses import dataclass

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ...solver.errors import ArticulaInputError
from . import bone_shapes
from ...solver.rig import names as rig_names
from ..scene.mesh_io import new_mesh, write_int_attribute, write_vertex_groups

FRAME_WARN = 1e-5      # rest frames that Blender cannot represent closer than this are reported

_PALETTE = {"L": 'THEME01', "R": 'THEME04', "": 'THEME09'}   # red left, blue right, yellow centre


@dataclass
class Rig:
    """The three objects of a rig; ``frame_error`` is the largest |Blender rest frame - model frame|
    (matrix entries) and ``warnings`` lists anything the caller should report."""
    armature: bpy.types.Object
    twist: bpy.types.Object
    mesh: bpy.types.Object
    frame_error: float = 0.0
    warnings: tuple = ()


def check_model(model, poses=None) -> None:
    """Raise :class:`ArticulaInputError` if ``model`` (and ``poses``) cannot be built as a rig."""
    model.validate()
    for i, name in enumerate(model.skeleton.names):
        why = rig_names.problem(name)
        if why:
            raise ArticulaInputError(f"bone_names: bone {i} name {name!r} {why}")
    if model.rest_vertices.shape[0] == 0:
        raise ArticulaInputError("rest_vertices: the model has no vertices")
    if poses is not None:
        poses.validate(model.skeleton.num_bones)


def build_rig(context, model, name: str = "Articula") -> Rig:
    """Create the rig of ``model`` in ``context.scene``; returns the :class:`Rig`.  The new main
    armature ends up active and selected, in object mode."""
    check_model(model)
    sk = model.skeleton
    with object_mode(context):
        arm, tw, mesh = create_objects(context, model, name)
        with edit_mode(context, arm):
            edit_main_bones(arm.data, sk)
        with edit_mode(context, tw):
            edit_twist_bones(tw.data, sk)
        pose_main(context.scene, arm, sk)
        pose_twist(tw, arm, sk)
        skin(mesh, model)
        finalize(context, arm, tw, mesh)
    err = frame_error(arm, sk)
    warnings = ()
    if err > FRAME_WARN:
        warnings = (f"Blender's bone rolls reproduce the rest frames only to {err:.2g} "
                    "(bones pointing almost exactly along -Y); deformation is exact for Blender's frames",)
    return Rig(arm, tw, mesh, err, warnings)


def frame_error(arm, sk) -> float:
    """Largest |matrix_local rotation - frames[b]| over the control bones of ``arm``."""
    got = np.array([np.array(arm.data.bones[n].matrix_local)[:3, :3] for n in sk.names])
    return float(np.abs(got - sk.frames).max())


# ----------------------------------------------------------------------------- stage 1: objects

def create_objects(context, model, name):
    """Stage 1 (object mode): the two armatures and the mesh, linked to the active collection, kinds set.
    Returns ``(armature, twist armature, mesh)`` objects."""
    coll = context.collection or context.scene.collection
    arm = bpy.data.objects.new(name, bpy.data.armatures.new(name))
    tw = bpy.data.objects.new(f"{name}.twist", bpy.data.armatures.new(f"{name}.twist"))
    mesh = bpy.data.objects.new(f"{name}.mesh", new_mesh(f"{name}.mesh", model.rest_vertices, model.faces))
    for ob, kind in ((arm, 'RIG_ARMATURE'), (tw, 'TWIST_ARMATURE'), (mesh, 'RIG_MESH')):
        coll.objects.link(ob)
        ob.articula.kind = kind
    arm.data.display_type = 'OCTAHEDRAL'
    return arm, tw, mesh


@contextmanager
def object_mode(context):
    """Leave edit/pose mode of whatever is active before the build (the build runs in object mode)."""
    if context.mode != 'OBJECT' and context.view_layer.objects.active is not None:
        bpy.ops.object.mode_set(mode='OBJECT')
    yield


@contextmanager
def edit_mode(context, ob):
    """Edit mode on ``ob`` alone (other objects deselected so multi-object editing stays out)."""
    for other in context.view_layer.objects:
        if other.select_get():
            other.select_set(False)
    context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    try:
        yield
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')
        ob.select_set(False)


# ----------------------------------------------------------------------------- stage 2: edit bones

def set_rest(eb, head, tail, frame):
    """Rest of an edit bone: head/tail as given, roll such that its axes are ``frame`` columns."""
    eb.head = Vector(head)
    eb.tail = Vector(tail)
    eb.roll = bpy.types.Bone.AxisRollFromMatrix(Matrix(frame.tolist()), axis=Vector(frame[:, 1]))[1]


def edit_main_bones(arm_data, sk):
    """Stage 2 (edit mode of the main armature): control bones in bundle order, then the swing helpers;
    bone collections Controls / Helpers (hidden) and side colours."""
    ctrl = arm_data.collections.new(rig_names.CONTROLS_COLLECTION)
    helpers = arm_data.collections.new(rig_names.HELPERS_COLLECTION)
    helpers.is_visible = False
    ebs = arm_data.edit_bones
    controls = []
    for b, name in enumerate(sk.names):
        eb = ebs.new(name)
        set_rest(eb, sk.heads[b], sk.tails[b], sk.frames[b])
        if b > 0:
            eb.parent = controls[sk.parents[b]]
        eb.use_deform = True
        eb.color.palette = _PALETTE[rig_names.side(name)]
        ctrl.assign(eb)
        controls.append(eb)
    for c in range(1, sk.num_bones):
        eb = ebs.new(rig_names.swing(sk.names[c]))
        set_rest(eb, sk.heads[c], sk.tails[c], sk.frames[c])
        eb.parent = controls[sk.parents[c]]
        eb.use_deform = True
        eb.hide = True
        helpers.assign(eb)


def edit_twist_bones(arm_data, sk):
    """Stage 2 (edit mode of the twist armature): unparented ``TW-<c>`` at the rest of c, and NEUTRAL."""
    coll = arm_data.collections.new(rig_names.TWIST_COLLECTION)
    ebs = arm_data.edit_bones
    for c in range(1, sk.num_bones):
        eb = ebs.new(rig_names.twist(sk.names[c]))
        set_rest(eb, sk.heads[c], sk.tails[c], sk.frames[c])
        eb.use_deform = True
        coll.assign(eb)
    eb = ebs.new(rig_names.NEUTRAL)
    set_rest(eb, sk.heads[0], sk.tails[0], sk.frames[0])
    eb.use_deform = True
    coll.assign(eb)


# ----------------------------------------------------------------------------- stage 3: pose pass

def lock(pb, location=True, rotation=True, scale=True):
    """Lock the transform channels of pose bone ``pb`` in the UI (drivers and constraints still act)."""
    pb.lock_location = (location,) * 3
    pb.lock_rotation = (rotation,) * 3
    pb.lock_rotation_w = rotation
    pb.lock_scale = (scale,) * 3


def pose_main(scene, arm, sk):
    """Stage 3 (object mode, pose data): rotation modes, locks, widgets, bundle indices of the control
    bones, and the Damped Track of every swing helper (target: this armature, by ID)."""
    circle, root = bone_shapes.widget(scene, "CIRCLE"), bone_shapes.widget(scene, "ROOT")
    for b, name in enumerate(sk.names):
        arm.data.bones[name][rig_names.BONE_INDEX_PROP] = b
        pb = arm.pose.bones[name]
        pb.rotation_mode = 'QUATERNION'
        pb.custom_shape = root if b == 0 else circle
        if b > 0:
            lock(pb, location=True, rotation=False, scale=True)
    for c in range(1, sk.num_bones):
        pb = arm.pose.bones[rig_names.swing(sk.names[c])]
        pb.rotation_mode = 'QUATERNION'
        lock(pb)
        con = pb.constraints.new('DAMPED_TRACK')
        con.name = "Articula Swing"
        con.target = arm
        con.subtarget = sk.names[c]
        con.head_tail = 1.0
        con.track_axis = 'TRACK_Y'


def pose_twist(tw, arm, sk):
    """Stage 3: the twist driver of every ``TW-<c>`` (Y Euler angle = SWING_TWIST_Y twist of control c)."""
    for c in range(1, sk.num_bones):
        pb = tw.pose.bones[rig_names.twist(sk.names[c])]
        pb.rotation_mode = 'XYZ'
        lock(pb)
        driver = pb.driver_add("rotation_euler", 1).driver
        driver.type = 'AVERAGE'
        var = driver.variables.new()
        var.name = "twist"
        var.type = 'TRANSFORMS'
        target = var.targets[0]
        target.id = arm                      # an ID reference: survives renames and linking
        target.bone_target = sk.names[c]
        target.transform_type = 'ROT_Y'
        target.rotation_mode = 'SWING_TWIST_Y'
        target.transform_space = 'LOCAL_SPACE'
    lock(tw.pose.bones[rig_names.NEUTRAL])


# ----------------------------------------------------------------------------- stage 4: skin

def skin_groups(model):
    """Vertex-group names ``(G,)`` and weights ``(V, G)`` float32 of the rig mesh: NEUTRAL (twist
    remainder), twist groups, swing groups, control groups (swing remainder on the anchor).

    NEUTRAL comes first on purpose: Blender's dual-quaternion blend aligns each bone's quaternion to
    the running sum in vertex-group order, so starting with the identity makes it align to the
    neutral, as the solver does (see :func:`twist_alignment_ok`)."""
    sk = model.skeleton
    V, B = model.num_vertices, sk.num_bones
    joints = np.arange(1, B)
    names = ([rig_names.NEUTRAL] + [rig_names.twist(sk.names[c]) for c in joints]
             + [rig_names.swing(sk.names[c]) for c in joints] + list(sk.names))
    tw = model.twist_weights[:, 1:].astype(np.float64)
    sw = model.swing_weights[:, 1:].astype(np.float64)
    anchor_col = np.zeros((V, B))
    anchor_col[np.arange(V), model.anchor] = 1.0 - sw.sum(axis=1)
    w = np.concatenate([1.0 - tw.sum(axis=1, keepdims=True), tw, sw, anchor_col], axis=1)
    return names, np.clip(w, 0.0, 1.0).astype(np.float32)


def skin(mesh, model):
    """Stage 4: vertex groups (:func:`skin_groups`) and the anchor attribute of the rig mesh."""
    names, weights = skin_groups(model)
    write_vertex_groups(mesh, names, weights)
    write_int_attribute(mesh.data, rig_names.ANCHOR_ATTRIBUTE, model.anchor)


def add_armature_modifier(mesh, name, target, preserve_volume):
    """An Armature modifier on ``mesh`` deforming by vertex groups only (no envelopes, no multi-modifier)."""
    mod = mesh.modifiers.new(name, 'ARMATURE')
    mod.object = target
    mod.use_vertex_groups = True
    mod.use_bone_envelopes = False
    mod.use_deform_preserve_volume = preserve_volume
    mod.use_multi_modifier = False
    return mod


def finalize(context, arm, tw, mesh):
    """Stage 5: the two modifiers in order (twist with Preserve Volume, then swing), parenting to the main
    armature at the identity, hiding the twist armature, the main armature active and selected."""
    add_armature_modifier(mesh, rig_names.TWIST_MODIFIER, tw, True)
    add_armature_modifier(mesh, rig_names.SWING_MODIFIER, arm, False)
    for child in (tw, mesh):
        child.parent = arm
        child.matrix_parent_inverse = Matrix.Identity(4)
    tw.hide_set(True)
    tw.hide_select = True
    context.view_layer.objects.active = arm
    arm.select_set(True)
