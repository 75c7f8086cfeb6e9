"""Blender half of retargeting through shared topology (:mod:`solver.retarget.topology`; dissertation
(model-adaptive mocap) Sec. 4.2.3, Fig. 4.17): two Articula rigs whose meshes share their polygons, the
source's action fitted onto the target through the one-to-one vertex correspondence and written as a
NEW action on the target (its previous action is kept; the source is only read).

Both rigs are read in their own armature space (:func:`addon.rig.reader.read_model`), so the target
performs the motion relative to its own object transform.  Three steps, so an operator can run the
middle one in a worker thread: :func:`read_inputs` (bpy, validates), :func:`solve` (no bpy),
:func:`write_result` (bpy); :func:`retarget_topology_rigs` runs them in a row.
"""
from dataclasses import dataclass, replace

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.retarget.topology import retarget_topology
from ...solver.rig.model import Model, Poses
from .. import compat
from ..jobs import scene_guard
from ..rig import actions, reader


@dataclass
class TopologyInputs:
    """What :func:`solve` needs, read from the scene: the two main armatures, their models (the target's
    faces are the source's: the polygons were checked equal, only Blender's triangulation may differ),
    the source poses of frames ``frame_start ..`` and the source action's name."""
    source_arm: bpy.types.Object
    target_arm: bpy.types.Object
    source_model: Model
    target_model: Model
    source_poses: Poses
    frame_start: int
    action_name: str


def _main_armature(ob, role: str):
    """The main armature of the rig ``ob`` belongs to (any of its three objects)."""
    if ob is None:
        raise ArticulaInputError(f"no {role} rig given")
    try:
        return reader.find_armature(ob.name)
    except ArticulaInputError:
        raise ArticulaInputError(f"{role} {ob.name!r} is not (part of) an Articula rig") from None


def _polygons(mesh_ob):
    """``(loop_total (P,), loop vertex indices (L,))`` int32 of a mesh object's polygons."""
    me = mesh_ob.data
    sizes = np.empty(len(me.polygons), dtype=np.int32)
    me.polygons.foreach_get("loop_total", sizes)
    loops = np.empty(len(me.loops), dtype=np.int32)
    me.loops.foreach_get("vertex_index", loops)
    return sizes, loops


def check_shared_polygons(source_mesh, target_mesh) -> None:
    """Raise :class:`ArticulaInputError` unless the two rig meshes have the same vertex count and the
    same polygons (vertex loops in the same order)."""
    (ss, sl), (ts, tl) = _polygons(source_mesh), _polygons(target_mesh)
    vs, vt = len(source_mesh.data.vertices), len(target_mesh.data.vertices)
    if vs != vt or len(ss) != len(ts):
        raise ArticulaInputError(
            f"the rig meshes do not share their topology: {source_mesh.name!r} has {vs} vertices and "
            f"{len(ss)} faces, {target_mesh.name!r} {vt} vertices and {len(ts)} faces")
    if not (np.array_equal(ss, ts) and np.array_equal(sl, tl)):
        starts = np.concatenate([[0], np.cumsum(ss)[:-1]])
        differ = [p for p in range(len(ss)) if ss[p] != ts[p] or not np.array_equal(
            sl[starts[p]:starts[p] + ss[p]], tl[starts[p]:starts[p] + ts[p]])]
        raise ArticulaInputError(
            f"the rig meshes do not share their topology: {source_mesh.name!r} and {target_mesh.name!r} both "
            f"have {vs} vertices and {len(ss)} faces, but {len(differ)} faces join other vertices "
            f"(the first is face {differ[0]})")


def _bone_curves(arm, action):
    return [fc for fc in compat.object_action_fcurves(arm, action) if fc.data_path.startswith("pose.bones[")]


def read_inputs(source, target, frame_start=None, frame_end=None) -> TopologyInputs:
    """Read and check the two rigs (any object of each) and the source's active action at integer frames
    ``frame_start .. frame_end`` (default: the action's keyed range)."""
    src, tgt = _main_armature(source, "source"), _main_armature(target, "target")
    if src == tgt:
        raise ArticulaInputError(f"the source and target are the same rig ({src.name!r})")
    action = src.animation_data.action if src.animation_data else None
    if action is None:
        raise ArticulaInputError(f"source rig {src.name!r} has no action to retarget")
    check_shared_polygons(reader.find_mesh(src), reader.find_mesh(tgt))
    if frame_start is None:
        frame_start = actions.action_frame_range(_bone_curves(src, action))[0]
    if frame_end is not None and frame_end < frame_start:
        raise ArticulaInputError(f"frames: the last frame {frame_end} is before the first {frame_start}")
    poses = reader.read_poses(src, action, frame_start, frame_end)
    src_model, tgt_model = reader.read_model(src), reader.read_model(tgt)
    return TopologyInputs(src, tgt, src_model, replace(tgt_model, faces=src_model.faces), poses,
                          int(frame_start), action.name)


def solve(inputs: TopologyInputs, scale=None, progress=None):
    """The fit (no bpy): ``(target poses, report)`` of :func:`solver.retarget.topology.retarget_topology`."""
    return retarget_topology(inputs.source_model, inputs.source_poses, inputs.target_model, scale=scale,
                             progress=progress)


def write_result(context, inputs: TopologyInputs, poses) -> bpy.types.Action:
    """Write ``poses`` as a new action on the target from ``inputs.frame_start`` on (made active; the
    replaced action is kept); nothing is left behind if writing fails."""
    name = f"{inputs.action_name} (topology from {inputs.source_arm.name})"
    with scene_guard():
        return actions.write_action(inputs.target_arm, inputs.target_model.skeleton.names, poses, name=name,
                                    frame_start=inputs.frame_start, scene=context.scene)


def retarget_topology_rigs(context, source_arm, target_arm, frame_start=None, frame_end=None, scale=None,
                           progress=None):
    """Retarget the source rig's active action onto the target rig through their shared mesh topology.

    source_arm, target_arm: objects of two Articula rigs (main armature, twist armature or rig mesh);
    frames: integer scene frames of the source action (default: its keyed range), written to the same
    frames on the target; scale: None, ``"height"`` or a size ratio (solver module docstring).
    Returns ``(action, report)``: the new target action and the solver's report (RMS in metres) with
    ``frame_start`` and the action names added."""
    inputs = read_inputs(source_arm, target_arm, frame_start, frame_end)
    poses, report = solve(inputs, scale, progress)
    action = write_result(context, inputs, poses)
    report.update(frame_start=inputs.frame_start, source_action=inputs.action_name, action=action.name)
    return action, report
