"""The motion of a retargeting source as armature-space pose matrices ``(F, J, 4, 4)``.

Fast path: the active action's F-curves are evaluated at every integer frame of its range (keys read
directly when they sit on every frame) and chained with Blender's pose rule in numpy; channels without an
F-curve hold the pose bone's current value; Euler (any order), quaternion and axis-angle rotations and
location/scale on any bone are read.  When Blender's evaluation would differ from that rule (bone
constraints, drivers, bones that do not inherit rotation or scale, NLA strips playing) the pose is read
from the evaluated scene frame by frame instead, which is exact but slower; the scene's current frame
is restored.
"""
import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.geometry.rotations import quat_normalize, quat_to_matrix, rotvec_to_matrix
from ...solver.retarget.armature import forward
from .. import compat
from ..rig.actions import action_frame_range, fcurve_values
from .armatures import constrained_bones, driven_bones

_AXES = {"X": 0, "Y": 1, "Z": 2}


def _axis_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i], R[..., j, j], R[..., i, j], R[..., j, i] = c, c, -s, s
    return R


def euler_to_matrix(angles: np.ndarray, order: str) -> np.ndarray:
    """(..., 3, 3) of Blender Euler angles ``(..., 3)`` (radians, X/Y/Z components) in rotation ``order``
    (e.g. 'XYZ': X is applied first, R = Rz·Ry·Rx)."""
    R = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for letter in order:
        a = _AXES[letter]
        R = _axis_rotation(a, angles[..., a]) @ R
    return R


def axis_angle_to_matrix(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) of Blender axis-angle values ``(..., 4)`` (angle, x, y, z; the axis normalised first)."""
    axis = v[..., 1:] / np.maximum(np.linalg.norm(v[..., 1:], axis=-1, keepdims=True), 1e-12)
    return rotvec_to_matrix(v[..., :1] * axis)


_ROTATION_PROP = {'QUATERNION': ("rotation_quaternion", 4), 'AXIS_ANGLE': ("rotation_axis_angle", 4)}


def active_action(ob):
    """The action ``ob`` plays, or a clear error when it has none."""
    ad = ob.animation_data
    if ad is None or ad.action is None:
        strips = ad is not None and any(t.strips for t in ad.nla_tracks)
        hint = " (it has NLA strips: make the one to retarget the active action)" if strips else \
            " (import a BVH with Blender's importer, bake a pose, or pick an animated rig)"
        raise ArticulaInputError(f"source {ob.name!r} has no active action{hint}")
    return ad.action


def with_ancestors(ob, bones) -> set:
    """``bones`` and all their ancestors (the bones whose pose decides where ``bones`` are)."""
    out = set()
    for name in bones:
        b = ob.data.bones.get(name)
        while b is not None and b.name not in out:
            out.add(b.name)
            b = b.parent
    return out


def needs_evaluation(ob, bones=None, nla: bool = True) -> list:
    """Why the source must be read from the evaluated scene ([] when the F-curves say it all); only the
    ``bones`` that matter (the mapped ones and their ancestors; default: all) are looked at; ``nla``:
    playing NLA strips count too."""
    relevant = with_ancestors(ob, bones) if bones is not None else {b.name for b in ob.data.bones}
    why = []
    if constrained_bones(ob, relevant):
        why.append("bone constraints")
    if set(driven_bones(ob)) & relevant:
        why.append("drivers")
    if any((not b.use_inherit_rotation or b.inherit_scale != 'FULL') and b.name in relevant for b in ob.data.bones):
        why.append("bones that do not inherit rotation or scale")
    ad = ob.animation_data
    if nla and ad and any(not t.mute and t.strips for t in ad.nla_tracks):
        why.append("NLA strips")
    return why


def frame_range(ob, action):
    """(first, last) integer frames of ``action`` on ``ob`` (its manual range if set, else its keys)."""
    if getattr(action, "use_frame_range", False):
        return int(round(action.frame_range[0])), int(round(action.frame_range[1]))
    curves = compat.object_action_fcurves(ob, action)
    if not curves:
        raise ArticulaInputError(f"the action {action.name!r} of {ob.name!r} has no F-curves")
    return action_frame_range(curves)


def _channels(ob, action, frames):
    """Per bone: ``(location (F,3), rotation matrices (F,3,3), scale (F,3))`` from F-curves or current values."""
    curves = {}
    for fc in compat.object_action_fcurves(ob, action):
        curves[(fc.data_path, fc.array_index)] = fc
    F = len(frames)

    def read(pb, prop, n):
        path = f'pose.bones["{bpy.utils.escape_identifier(pb.name)}"].{prop}'
        now = list(getattr(pb, prop))
        return np.stack([fcurve_values(curves[(path, i)], frames) if (path, i) in curves
                         else np.full(F, float(now[i])) for i in range(n)], -1)
    out = []
    for pb in ob.pose.bones:
        mode = pb.rotation_mode
        if mode in _ROTATION_PROP:
            prop, n = _ROTATION_PROP[mode]
            values = read(pb, prop, n)
            R = quat_to_matrix(quat_normalize(values)) if mode == 'QUATERNION' else axis_angle_to_matrix(values)
        else:
            R = euler_to_matrix(read(pb, "rotation_euler", 3), mode)
        out.append((pb.name, read(pb, "location", 3), R, read(pb, "scale", 3)))
    return {name: (loc, R, scale) for name, loc, R, scale in out}


def local_from_fcurves(ob, arm, action, frames) -> np.ndarray:
    """(F, J, 4, 4) pose-bone matrices of rest armature ``arm`` (bone order) at ``frames``, from
    ``action``'s F-curves (channels without one: the pose bone's current value)."""
    ch = _channels(ob, action, frames)
    local = np.zeros((len(frames), len(arm.bones), 4, 4))
    for b, name in enumerate(arm.bones):
        loc, R, scale = ch[name]
        local[:, b, :3, :3] = R * scale[:, None, :]
        local[:, b, :3, 3] = loc
        local[:, b, 3, 3] = 1.0
    return local


def pose_from_fcurves(ob, arm, action, frames) -> np.ndarray:
    """(F, J, 4, 4) armature-space pose matrices of rest armature ``arm`` (bone order) at ``frames``."""
    return forward(arm, local_from_fcurves(ob, arm, action, frames))


def pose_from_scene(ob, arm, frames, progress=None) -> np.ndarray:
    """(F, J, 4, 4) armature-space pose matrices read from the evaluated scene at ``frames``."""
    scene = bpy.context.scene
    keep = scene.frame_current
    bones = [ob.pose.bones[n] for n in arm.bones]
    out = np.empty((len(frames), len(bones), 4, 4))
    try:
        for k, f in enumerate(frames):
            scene.frame_set(int(f))
            for b, pb in enumerate(bones):
                out[k, b] = np.array(pb.matrix, dtype=np.float64)
            if progress is not None and k % 50 == 0:
                progress(k / len(frames), f"reading the source's frame {f}")
    finally:
        scene.frame_set(keep)
    return out


def read_clip(ob, arm, bones=None, progress=None):
    """``(frames (F,), pose (F, J, 4, 4), how)`` of source object ``ob``'s active action; ``bones``: the
    mapped bones (constraints or drivers elsewhere do not force the slow evaluated path)."""
    action = active_action(ob)
    first, last = frame_range(ob, action)
    if last < first:
        raise ArticulaInputError(f"the action {action.name!r} has an empty frame range")
    frames = np.arange(first, last + 1)
    why = needs_evaluation(ob, bones)
    if why:
        return frames, pose_from_scene(ob, arm, frames, progress), "evaluated (" + ", ".join(why) + ")"
    return frames, pose_from_fcurves(ob, arm, action, frames), "F-curves"
