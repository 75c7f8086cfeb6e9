"""A retargeted clip written as a NEW action on the target armature (4.2 legacy and 5.x slotted actions
through :mod:`addon.compat`).

Each keyed bone gets its rotation in the bone's own rotation mode (quaternions; Euler angles in the
bone's order, unwrapped from frame to frame; axis-angle), LINEAR keys on the source's frames, and the
root bone its location.  The target's previous active action is kept (fake user when nothing else uses
it); nothing is overwritten.
"""
import numpy as np

from ...solver.geometry.rotations import quat_to_matrix
from .. import compat
from ..rig.actions import add_keys

_AXES = {"X": 0, "Y": 1, "Z": 2}


def matrix_to_euler(R: np.ndarray, order: str) -> np.ndarray:
    """(F, 3) Blender Euler angles (X/Y/Z components, radians) of rotations ``R (F, 3, 3)`` in ``order``
    ('XYZ' means R = Rz·Ry·Rx), unwrapped along the frames."""
    i, j, k = (_AXES[c] for c in order)
    sign = 1.0 if (j - i) % 3 == 1 else -1.0      # cyclic order (XYZ, YZX, ZXY) or not
    a = np.empty((len(R), 3))
    a[:, j] = np.arcsin(np.clip(-sign * R[:, k, i], -1.0, 1.0))
    a[:, i] = np.arctan2(sign * R[:, k, j], R[:, k, k])
    a[:, k] = np.arctan2(sign * R[:, j, i], R[:, i, i])
    return np.unwrap(a, axis=0)


def _axis_angle(q: np.ndarray) -> np.ndarray:
    """(F, 4) Blender axis-angle (angle, x, y, z) of unit quaternions ``q (F, 4)``."""
    w = np.clip(q[:, 0], -1.0, 1.0)
    angle = 2 * np.arccos(w)
    axis = q[:, 1:] / np.maximum(np.linalg.norm(q[:, 1:], axis=1, keepdims=True), 1e-12)
    axis[np.linalg.norm(q[:, 1:], axis=1) < 1e-12] = (0.0, 1.0, 0.0)
    return np.concatenate([angle[:, None], axis], axis=1)


def bone_channels(pb, q: np.ndarray) -> list:
    """``[(prop, index, values (F,))]`` of the rotation of pose bone ``pb`` from quaternions ``q (F, 4)``."""
    mode = pb.rotation_mode
    if mode == 'QUATERNION':
        return [("rotation_quaternion", i, q[:, i]) for i in range(4)]
    if mode == 'AXIS_ANGLE':
        aa = _axis_angle(q)
        return [("rotation_axis_angle", i, aa[:, i]) for i in range(4)]
    e = matrix_to_euler(quat_to_matrix(q), mode)
    return [("rotation_euler", i, e[:, i]) for i in range(3)]


def write_clip(arm_ob, rest, result, frames, name: str):
    """Write ``result`` (:class:`solver.retarget.solve.RetargetResult`, bones in ``rest`` order) on
    ``frames`` to a new action named ``name`` on armature object ``arm_ob``; returns the action."""
    action, slot, bag = compat.new_object_action(name, arm_ob)
    for b in result.driven:
        bone = rest.bones[b]
        curves = bone_channels(arm_ob.pose.bones[bone], result.quaternions[:, b])
        if b == result.root_bone:
            curves += [("location", i, result.root_locations[:, i]) for i in range(3)]
        for prop, index, values in curves:
            add_keys(bag, bone, prop, index, frames, values)
    old = arm_ob.animation_data.action if arm_ob.animation_data else None
    if old is not None and old.users == 1 and not old.use_fake_user:
        old.use_fake_user = True
    compat.assign_action(arm_ob, action, slot)
    return action
