"""A gaze shot as its own NLA layer on top of the character's animation.

The armature's active action (if any) is first pushed down into an NLA strip of its own, unchanged (its
keys are never touched; Blender evaluates the active action *above* the NLA, so a layer over it needs
it in the stack).  Each shot is then a strip of a new action on the track "Articula Gaze" (a new track
when it would overlap a strip there) spanning exactly the shot's frames, blend type COMBINE, no
extrapolation: outside the shot nothing changes.  COMBINE post-multiplies quaternions (value = below ·
strip) and adds Euler angles, so the strip holds ``q_belowᵀ q_new`` or ``e_new − e_below``.  Mute,
tweak or delete the strip or track in the NLA editor to undo a shot.
"""
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.geometry.rotations import matrix_to_quat, quat_conj, quat_mul
from .. import compat
from ..retarget.clip_writer import matrix_to_euler
from ..rig.actions import add_keys

TRACK = "Articula Gaze"


def push_down_active_action(arm_ob) -> str:
    """Put the active action on an NLA track of its own (frame range = the action's); returns a note
    when its F-curves extrapolate other than constantly (the strip holds its ends instead)."""
    ad = arm_ob.animation_data
    if ad is None or ad.action is None:
        return ""
    action, slot = ad.action, getattr(ad, "action_slot", None)
    first = int(np.floor(action.frame_range[0]))
    curves = compat.object_action_fcurves(arm_ob, action)
    track = compat.push_to_nla(arm_ob, action, slot, first)
    track.strips[0].extrapolation = 'HOLD'
    ad.action = None
    moving = [fc for fc in curves if fc.extrapolation != 'CONSTANT' or any(m.type == 'CYCLES' for m in fc.modifiers)]
    return (f"the action {action.name!r} now plays from an NLA strip; {len(moving)} of its F-curves extrapolate "
            "(cycles or linear), which the strip holds at its ends instead") if moving else ""


def check_rotation_modes(arm_ob, names) -> None:
    """Refuse before anything changes when a bone of ``names`` rotates in axis-angle mode (COMBINE cannot
    layer axis-angle channels)."""
    for name in names:
        if arm_ob.pose.bones[name].rotation_mode == 'AXIS_ANGLE':
            raise ArticulaInputError(f"bone {name!r} uses axis-angle rotation, which an NLA layer cannot combine: "
                                     "set its rotation mode to Quaternion or an Euler order")


def _channels(pb, below: np.ndarray, new: np.ndarray) -> list:
    """``[(prop, index, values)]`` that COMBINE onto ``below`` (F, 3, 3) to give ``new`` (F, 3, 3)."""
    mode = pb.rotation_mode
    if mode == 'QUATERNION':
        q = quat_mul(quat_conj(matrix_to_quat(below)), matrix_to_quat(new))
        q[q[:, 0] < 0] *= -1
        return [("rotation_quaternion", i, q[:, i]) for i in range(4)]
    e0, e1 = matrix_to_euler(below, mode), matrix_to_euler(new, mode)
    d = e1 - e0
    d -= 2 * np.pi * np.round(d / (2 * np.pi))
    return [("rotation_euler", i, d[:, i]) for i in range(3)]


def _free_track(ad, start: int, end: int):
    """The gaze track with room for ``start..end``, made when needed (above everything)."""
    for track in reversed(list(ad.nla_tracks)):
        if track.name.startswith(TRACK):
            if all(s.frame_end < start or s.frame_start > end for s in track.strips):
                return track
            break
    track = ad.nla_tracks.new()
    track.name = TRACK
    return track


def add_shot(arm_ob, rest, bones, frames, below, new, name: str):
    """New strip with the shot's correction of ``bones`` (indices into ``rest``): pose-bone rotations
    ``below``/``new`` ``(F, J, 3, 3)`` on ``frames``; returns the strip."""
    action, slot, bag = compat.new_object_action(name, arm_ob)
    for b in bones:
        pb = arm_ob.pose.bones[rest.bones[b]]
        for prop, index, values in _channels(pb, below[:, b], new[:, b]):
            add_keys(bag, pb.name, prop, index, frames, values)
    ad = arm_ob.animation_data or arm_ob.animation_data_create()
    track = _free_track(ad, int(frames[0]), int(frames[-1]))
    strip = track.strips.new(action.name, int(frames[0]), action)
    if slot is not None and getattr(strip, "action_slot", None) != slot:
        strip.action_slot = slot
    strip.blend_type = 'COMBINE'
    strip.extrapolation = 'NOTHING'
    return strip
