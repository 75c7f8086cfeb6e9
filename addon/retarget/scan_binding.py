"""Drive a detailed static scan with a fitted Articula rig (direct animation of reconstructed data,
dissertation ch. 4, Sec. 4.2.3): Blender's Surface Deform modifier on the scan, targeting the rig mesh,
bound in the pose where scan and model coincide.  No Python runs at frame time.

The binding is made with the rig in the current frame's pose (``'CURRENT'``, the pose the model was
fitted to the scan in) or at its rest pose (``'REST'``: both armatures of the rig switched to Rest
Position for the bind).  The modifier is named :data:`MODIFIER`; binding again replaces it (same place
in the stack).  Every failure raises ``ArticulaInputError`` and leaves the scene as it was.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.rig import names as rig_names
from ..rig import reader as rig_reader
from ..scene.mesh_io import read_positions

MODIFIER = "Articula Scan Binding"
BIND_POSES = (
    ('CURRENT', "Current Pose", "Bind with the rig in the current frame's pose (the pose the model was fitted "
                                "to the scan in)"),
    ('REST', "Rest Pose", "Bind with the rig at its rest pose (the scan lies on the rig's rest mesh)"),
)
_RIG_KINDS = ('RIG_ARMATURE', 'RIG_MESH', 'TWIST_ARMATURE')


@dataclass
class Binding:
    """A made binding: the scan, the rig's main armature and mesh, the modifier, the bind time (s)."""
    scan: bpy.types.Object
    armature: bpy.types.Object
    rig_mesh: bpy.types.Object
    modifier: bpy.types.Modifier
    bind_pose: str
    seconds: float
    warnings: tuple = ()


# ----------------------------------------------------------------------------- finding the inputs

def find_scan(name: str = "", context=None) -> bpy.types.Object:
    """The scan object ``name``, else the active object, else the one selected mesh that is not part
    of an Articula rig."""
    context = context or bpy.context
    if name:
        ob = bpy.data.objects.get(name)
        if ob is None:
            raise ArticulaInputError(f"scan: no object named {name!r}")
        return ob
    ob = context.active_object
    if ob is not None and ob.type == 'MESH' and ob.articula.kind not in _RIG_KINDS:
        return ob
    meshes = [o for o in context.selected_objects if o.type == 'MESH' and o.articula.kind not in _RIG_KINDS]
    if len(meshes) != 1:
        raise ArticulaInputError("select the scan mesh (and the rig), or name the scan")
    return meshes[0]


def find_rig(name: str = "", context=None) -> bpy.types.Object:
    """The main armature of the rig ``name`` (armature, rig mesh or twist armature), else of the selected
    rig object, else of the scene's only Articula rig."""
    context = context or bpy.context
    if name:
        if bpy.data.objects.get(name) is None:
            raise ArticulaInputError(f"rig: no object named {name!r}")
        return rig_reader.find_armature(name, context)
    for ob in [context.active_object] + list(context.selected_objects):
        if ob is not None and ob.articula.kind in _RIG_KINDS:
            return rig_reader.find_armature(ob.name, context)
    rigs = [o for o in context.scene.objects if o.type == 'ARMATURE' and o.articula.kind == 'RIG_ARMATURE']
    if len(rigs) != 1:
        raise ArticulaInputError("select the Articula rig (or its mesh) with the scan, or name the rig")
    return rigs[0]


def check_scan(scan, rig_mesh) -> None:
    """Refuse a scan the binding cannot use, with a message naming it and the problem."""
    if scan.type != 'MESH':
        raise ArticulaInputError(f"scan {scan.name!r} is a {scan.type.lower()} object, not a mesh")
    if scan == rig_mesh or scan.articula.kind in _RIG_KINDS:
        raise ArticulaInputError(f"scan {scan.name!r} is part of an Articula rig; choose the scan mesh")
    if scan.library is not None:
        raise ArticulaInputError(f"scan {scan.name!r} is linked from {scan.library.filepath!r}; make it local "
                                 "(Object > Relations > Make Local) to add a modifier")
    if len(scan.data.vertices) == 0:
        raise ArticulaInputError(f"scan {scan.name!r} has no vertices")
    for mod in scan.modifiers:
        if mod.type == 'SURFACE_DEFORM' and mod.name != MODIFIER and mod.target == rig_mesh:
            raise ArticulaInputError(f"scan {scan.name!r} already has a Surface Deform modifier {mod.name!r} "
                                     f"targeting {rig_mesh.name!r}; remove it (or name it {MODIFIER!r} to "
                                     "have it replaced)")


# ----------------------------------------------------------------------------- binding

@contextlib.contextmanager
def _bind_pose(context, arm, rig_mesh, bind_pose: str):
    """Hold the rig in ``bind_pose`` inside the block (REST: both armatures at Rest Position), restore after."""
    if bind_pose not in {k for k, _, _ in BIND_POSES}:
        raise ArticulaInputError(f"bind pose {bind_pose!r}: use one of {', '.join(k for k, _, _ in BIND_POSES)}")
    datas = []
    if bind_pose == 'REST':
        twist = rig_mesh.modifiers.get(rig_names.TWIST_MODIFIER)
        for ob in (arm, twist.object if twist is not None else None):
            if ob is not None and ob.type == 'ARMATURE' and ob.data not in [d for d, _ in datas]:
                datas.append((ob.data, ob.data.pose_position))
                ob.data.pose_position = 'REST'
        context.view_layer.update()
    try:
        yield
    finally:
        for data, position in datas:
            data.pose_position = position
        if datas:
            context.view_layer.update()


def bind_scan(context, scan, arm, bind_pose: str = 'CURRENT') -> Binding:
    """Bind ``scan`` to the rig whose main armature is ``arm`` with a Surface Deform modifier (see the
    module docstring).  Raises ``ArticulaInputError`` (scene unchanged) when Blender cannot bind."""
    rig_mesh = rig_reader.find_mesh(arm)
    check_scan(scan, rig_mesh)
    old = scan.modifiers.get(MODIFIER)
    shown = (old.show_viewport, old.show_render) if old is not None else None
    mod = None
    try:
        with _bind_pose(context, arm, rig_mesh, bind_pose):
            if old is not None:       # the new binding must see the undeformed scan
                old.show_viewport = old.show_render = False
            mod = scan.modifiers.new(MODIFIER + ".new", 'SURFACE_DEFORM')
            mod.target = rig_mesh
            context.view_layer.update()
            t0 = time.perf_counter()
            with context.temp_override(object=scan, active_object=scan):
                bpy.ops.object.surfacedeform_bind(modifier=mod.name)
            if not mod.is_bound:
                context.view_layer.update()
            seconds = time.perf_counter() - t0
            if not mod.is_bound:
                raise ArticulaInputError(f"cannot bind scan {scan.name!r} to {rig_mesh.name!r}: "
                                         f"{target_problem(rig_mesh, context)}")
    except BaseException:
        if mod is not None:
            scan.modifiers.remove(mod)
        if old is not None:
            old.show_viewport, old.show_render = shown
        context.view_layer.update()
        raise
    if old is not None:
        index = scan.modifiers.find(old.name)
        scan.modifiers.remove(old)
        scan.modifiers.move(len(scan.modifiers) - 1, index)
    mod.name = MODIFIER
    context.view_layer.update()
    return Binding(scan, arm, rig_mesh, mod, bind_pose, seconds, _alignment_warnings(scan, rig_mesh, context))


def unbind_scan(scan) -> bool:
    """Remove the binding modifier from ``scan``; False when it had none."""
    mod = scan.modifiers.get(MODIFIER)
    if mod is None:
        return False
    scan.modifiers.remove(mod)
    return True


# ----------------------------------------------------------------------------- diagnosis and report

def _world_box(ob, context):
    """(min, max) world corners of ``ob``'s evaluated bounding box."""
    ev = ob.evaluated_get(context.evaluated_depsgraph_get())
    mw = np.array(ev.matrix_world)
    corners = np.array([tuple(c) for c in ev.bound_box], np.float64) @ mw[:3, :3].T + mw[:3, 3]
    return corners.min(0), corners.max(0)


def _alignment_warnings(scan, rig_mesh, context) -> tuple:
    """A warning when the scan's bounding box hardly overlaps the rig mesh's (scan not aligned)."""
    (a0, a1), (b0, b1) = _world_box(scan, context), _world_box(rig_mesh, context)
    inter = np.clip(np.minimum(a1, b1) - np.maximum(a0, b0), 0, None)
    size = np.maximum(np.minimum(a1 - a0, b1 - b0), 1e-9)
    if np.any(inter < 0.5 * size):
        return (f"the bounding boxes of {scan.name!r} and {rig_mesh.name!r} hardly overlap: the scan should lie "
                "on the rig in the bind pose",)
    return ()


def target_problem(rig_mesh, context) -> str:
    """Why Surface Deform refuses to bind (its checks: target faces present, at most two polygons per
    edge, convex polygons with no repeated or collinear corners; scan vertices exactly on target edges
    make it fail too, reported on the console as "invalid polygons")."""
    ev = rig_mesh.evaluated_get(context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    try:
        if len(me.polygons) == 0:
            return f"the rig mesh {rig_mesh.name!r} has no faces"
        edges = np.empty(len(me.loops), np.int32)
        me.loops.foreach_get("edge_index", edges)
        shared = np.flatnonzero(np.bincount(edges, minlength=len(me.edges)) > 2)
        if shared.size:
            return (f"{shared.size} edges of the rig mesh {rig_mesh.name!r} have more than two polygons "
                    f"(first: edge {int(shared[0])})")
        bad = _bad_polygons(me)
        if bad.size:
            return (f"{bad.size} polygons of the rig mesh {rig_mesh.name!r} are concave or degenerate "
                    f"(first: polygon {int(bad[0])}); Blender's Surface Deform needs convex polygons")
    finally:
        ev.to_mesh_clear()
    return ("Blender's Surface Deform bound no vertex; it fails this way when scan vertices lie exactly on the "
            "rig mesh's edges (a scan made by subdividing the rig mesh must be displaced slightly); its "
            "reason is printed on the console")


def _bad_polygons(me) -> np.ndarray:
    """Indices of polygons that are concave or degenerate (a corner turning against the polygon normal,
    or a zero cross product)."""
    pos = read_positions(me)
    corners = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", corners)
    sizes = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_total", sizes)
    normals = np.empty(3 * len(me.polygons), np.float32)
    me.polygons.foreach_get("normal", normals)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    face = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(len(corners)) - starts[face]
    p, prev = pos[corners], pos[corners[starts[face] + (local - 1) % sizes[face]]]
    after = pos[corners[starts[face] + (local + 1) % sizes[face]]]
    cross = np.cross(p - prev, after - p)
    scale = np.linalg.norm(p - prev, axis=1) * np.linalg.norm(after - p, axis=1)
    turn = np.einsum("ij,ij->i", cross, normals.reshape(-1, 3).astype(np.float64)[face])
    return np.unique(face[turn <= 1e-9 * np.maximum(scale, 1e-30)])


def summary(binding: Binding) -> str:
    """One line: what was bound to what, in which pose, how long it took (warnings apart)."""
    pose = dict((k, n) for k, n, _ in BIND_POSES)[binding.bind_pose].lower()
    text = (f"bound {binding.scan.name!r} ({len(binding.scan.data.vertices):,} vertices) to rig mesh "
            f"{binding.rig_mesh.name!r} at the {pose} in {binding.seconds:.2f} s")
    return text
