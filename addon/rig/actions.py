"""Poses <-> actions on the control bones of an Articula rig.

Writing uses the fast keyframe path (one ``keyframe_points.add`` + ``foreach_set`` per F-curve) into a
NEW action (Blender makes the name unique, so nothing is overwritten): ``rotation_quaternion`` of every
control bone, and ``location``/``scale`` of the root bone, on frames ``frame_start .. frame_start+N-1``
with LINEAR interpolation.  Conventions (docs/skinning.md, model bundle):

* rotations (N,B,4) are the pose-bone quaternions (w,x,y,z) in bone-local axes; consecutive keys are
  sign-aligned (q and -q are the same rotation) so interpolated sub-frames take the short way;
* the root translation t (world metres) is stored as the root bone's location in its rest axes,
  ``F0ᵀ t`` (F0 = the root bone's rest matrix as Blender holds it), and the uniform scale s as
  scale (s, s, s).

Reading evaluates the F-curves at integer frames (keys read directly when they sit on every frame)
and returns :class:`solver.rig.model.Poses` with normalised quaternions; channels without an F-curve read
as the rest value.
"""
import os
import re

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.geometry.rotations import quat_sign_continuous
from ...solver.rig.model import Poses
from .. import compat
from ..scene import frames

_LINEAR = None


def _linear():
    global _LINEAR
    if _LINEAR is None:
        _LINEAR = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["LINEAR"].value
    return _LINEAR


def _path(bone: str, prop: str) -> str:
    return f'pose.bones["{bpy.utils.escape_identifier(bone)}"].{prop}'


def add_keys(channels, bone: str, prop: str, index: int, frames, values) -> None:
    """A new F-curve of pose bone ``bone``'s ``prop[index]`` in ``channels`` (:func:`compat.new_object_action`)
    with LINEAR keys ``values (N,)`` on ``frames (N,)``, written in one ``foreach_set``."""
    co = np.empty((len(frames), 2), dtype=np.float32)
    co[:, 0], co[:, 1] = frames, values
    fc = compat.fcurve_new(channels, _path(bone, prop), index, bone)
    fc.keyframe_points.add(len(frames))
    fc.keyframe_points.foreach_set("co", co.ravel())
    fc.keyframe_points.foreach_set("interpolation", np.full(len(frames), _linear(), dtype=np.int32))
    fc.update()


def root_rest_axes(arm, root: str) -> np.ndarray:
    """(3, 3) rest axes (columns) of bone ``root`` as Blender holds them (float32 values)."""
    return np.array(arm.data.bones[root].matrix_local, dtype=np.float64)[:3, :3]


def channels(names, poses, root_axes):
    """``[(bone, prop, index, values (N,))]`` of every F-curve to write for ``poses``."""
    q = quat_sign_continuous(poses.rotations)
    loc = poses.translations @ root_axes                 # rows: F0ᵀ t
    out = [(name, "rotation_quaternion", i, q[:, b, i]) for b, name in enumerate(names) for i in range(4)]
    out += [(names[0], "location", i, loc[:, i]) for i in range(3)]
    out += [(names[0], "scale", i, poses.scales) for i in range(3)]
    return out


def _base_name(name: str, word: str) -> str:
    """``name`` without Blender's ``.001`` suffix and without a trailing `` <word>`` (repeated)."""
    name = re.sub(r"\.\d{3,}$", "", name.strip())
    while name.endswith(" " + word):
        name = name[:-len(word) - 1]
    return name


def tracked_action_name(rig: str, recording: str) -> str:
    """``"<rig> tracked <recording>"``: the action of the motion tracked in ``recording`` (an object's
    name, or a path: its file or folder name without extension) on ``rig``.  A rig that tracking built is
    already named ``"<model> tracked"``; the word is said once, so tracking again never piles it up."""
    if os.sep in recording:
        recording = os.path.splitext(os.path.basename(os.path.normpath(recording)))[0]
    return f"{_base_name(rig, 'tracked')} tracked {recording}".strip()


def adapted_rig_name(rig: str) -> str:
    """``"<rig> adapted"``, said once: adapting an adapted rig again gives the same base name (Blender
    adds ``.001``)."""
    return f"{_base_name(rig, 'adapted')} adapted"


def write_action(arm, names, poses, name: str = "Articula Poses", frame_start: int = 1,
                 nla: bool = False, scene=None):
    """Write ``poses`` (N frames, bones ``names`` in bundle order) to a new action on armature object
    ``arm`` and make it active (or, when ``nla``, put it on a new NLA track and leave the active action
    alone).  A replaced active action without other users gets a fake user so it is not lost.  The scene's
    frame range covers the action (set outright when the scene holds only this rig, else only widened).
    Returns the action."""
    poses.validate(len(names))
    missing = [n for n in names if n not in arm.pose.bones]
    if missing:
        raise ArticulaInputError(f"armature {arm.name!r} has no bone {missing[0]!r}")
    N = len(poses)
    old = arm.animation_data.action if arm.animation_data else None
    action, slot, bag = compat.new_object_action(name, arm)
    on = np.arange(frame_start, frame_start + N)
    for bone, prop, index, values in channels(names, poses, root_rest_axes(arm, names[0])):
        add_keys(bag, bone, prop, index, on, values)
    if nla:
        compat.push_to_nla(arm, action, slot, frame_start)        # the active action stays as it is
    else:
        if old is not None and old.users == 1 and not old.use_fake_user:
            old.use_fake_user = True                               # keep the replaced action
        compat.assign_action(arm, action, slot)
    scene = scene or bpy.context.scene
    frames.include_frames(scene, frame_start, frame_start + max(N, 1) - 1, _rig_objects(arm))
    return action



def _rig_objects(arm) -> list:
    """The objects that make up the rig of armature object ``arm``: itself, its children (twist armature,
    mesh) and its bones' widget shapes."""
    widgets = {pb.custom_shape for pb in arm.pose.bones if pb.custom_shape is not None}
    return [arm, *arm.children_recursive, *widgets]


def fcurve_values(fc, frames) -> np.ndarray:
    """Values of F-curve ``fc`` at integer ``frames`` (read straight from the keys when they match)."""
    n = len(fc.keyframe_points)
    if n == len(frames):
        co = np.empty(2 * n, dtype=np.float32)
        fc.keyframe_points.foreach_get("co", co)
        co = co.reshape(-1, 2)
        if np.array_equal(co[:, 0], frames.astype(np.float32)):
            return co[:, 1].astype(np.float64)
    return np.array([fc.evaluate(float(f)) for f in frames])


def action_frame_range(fcurves):
    """(first, last) integer frames spanned by the keys of ``fcurves``."""
    ends = [fc.range() for fc in fcurves if len(fc.keyframe_points)]
    if not ends:
        raise ArticulaInputError("the action has no keyframes on the rig's bones")
    return int(np.floor(min(e[0] for e in ends))), int(np.ceil(max(e[1] for e in ends)))


def read_action(arm, names, action=None, frame_start=None, frame_end=None) -> Poses:
    """Poses of the bones ``names`` (bundle order) of armature object ``arm`` from ``action`` (default:
    the active action) at integer frames ``frame_start..frame_end`` (default: the keyed range)."""
    action = action or (arm.animation_data.action if arm.animation_data else None)
    if action is None:
        raise ArticulaInputError(f"armature {arm.name!r} has no active action")
    wanted = {(n, p) for n in names for p in ("rotation_quaternion", "location", "scale")}
    curves = {}
    for fc in compat.object_action_fcurves(arm, action):
        for n, p in wanted:
            if fc.data_path == _path(n, p):
                curves[(n, p, fc.array_index)] = fc
    if not curves:
        raise ArticulaInputError(f"action {action.name!r} animates none of the bones of {arm.name!r}")
    lo, hi = action_frame_range(curves.values())
    frames = np.arange(lo if frame_start is None else frame_start, (hi if frame_end is None else frame_end) + 1)

    def values(bone, prop, index, rest):
        fc = curves.get((bone, prop, index))
        return np.full(len(frames), rest) if fc is None else fcurve_values(fc, frames)

    rot = np.stack([np.stack([values(n, "rotation_quaternion", i, float(i == 0)) for i in range(4)], -1)
                    for n in names], axis=1)
    norm = np.linalg.norm(rot, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        f, b = np.argwhere(norm[..., 0] < 1e-12)[0]
        raise ArticulaInputError(f"action {action.name!r}: bone {names[b]!r} has a zero quaternion at frame {frames[f]}")
    loc = np.stack([values(names[0], "location", i, 0.0) for i in range(3)], -1)
    scale = np.stack([values(names[0], "scale", i, 1.0) for i in range(3)], -1)
    return _poses(arm, names, rot / norm, loc, scale, f"action {action.name!r}", [f"frame {f}" for f in frames])


def _poses(arm, names, rot, loc, scale, what: str, when: list) -> Poses:
    """Articula poses from the channels of ``names``: unit quaternions ``rot (N, B, 4)`` and the root's
    ``loc``/``scale (N, 3)`` in its pose-bone axes; refuses a non-uniform root scale (``what``/``when``
    name it)."""
    spread = np.abs(scale - scale.mean(axis=1, keepdims=True)).max(axis=1)
    if np.any(spread > 1e-6 * np.abs(scale).max(axis=1)):
        f = int(np.argmax(spread))
        raise ArticulaInputError(f"{what}: root bone {names[0]!r} has a non-uniform scale {tuple(scale[f])} "
                                 f"at {when[f]}; Articula poses need a uniform scale")
    trans = loc @ root_rest_axes(arm, names[0]).T
    return Poses(rot, trans, scale.mean(axis=1))


def current_pose(arm, names) -> Poses:
    """The pose (one frame) the bones ``names`` of armature object ``arm`` hold now (pose mode edits
    included, keyed or not), in the convention of :func:`read_action`."""
    bones = arm.pose.bones
    missing = [n for n in names if n not in bones]
    if missing:
        raise ArticulaInputError(f"armature {arm.name!r} has no pose bone {missing[0]!r}")
    for n in names:
        if bones[n].rotation_mode != 'QUATERNION':
            raise ArticulaInputError(f"armature {arm.name!r}: bone {n!r} uses rotation mode "
                                     f"{bones[n].rotation_mode}; Articula rigs use quaternions")
    rot = np.array([[list(bones[n].rotation_quaternion) for n in names]], np.float64)
    norm = np.linalg.norm(rot, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ArticulaInputError(f"armature {arm.name!r}: bone {names[int(np.argmin(norm[0, :, 0]))]!r} "
                                 f"has a zero quaternion")
    root = bones[names[0]]
    return _poses(arm, names, rot / norm, np.array([list(root.location)]), np.array([list(root.scale)]),
                  f"armature {arm.name!r}", ["its current pose"])
