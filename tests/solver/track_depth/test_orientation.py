"""The model's rest axes and the recording's up (solver.track_depth.orientation): closed forms on a
Blender-standing template, the same template rotated to stand along +Y, and floors in turned worlds."""
import numpy as np

from articula.solver.rig.model import Model, Skeleton
from articula.solver.track_depth.orientation import recording_up, rest_axes, rest_height
from articula.solver.track_depth.template import load_template


def _rotation(axis, degrees):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(degrees)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def _turned(model, R):
    sk = model.skeleton
    turned = Skeleton(list(sk.names), sk.parents, sk.heads @ R.T, sk.tails @ R.T, R @ sk.frames)
    return Model(model.rest_vertices @ R.T, model.faces, turned, model.anchor, model.twist_weights,
                 model.swing_weights)


def test_blender_standing_body_is_z_up_facing_minus_y():
    base = load_template().base
    up, front = rest_axes(base)
    assert up @ [0, 0, 1] > 0.99 and front @ [0, -1, 0] > 0.99 and abs(up @ front) < 1e-9
    assert abs(rest_height(base) - np.ptp(base.rest_vertices[:, 2])) < 0.02


def test_axes_turn_with_the_rest_body():
    base = load_template().base
    for R in (_rotation([1, 0, 0], -90.0), _rotation([1, 1, 0], 30.0), _rotation([0, 1, 0], 180.0)):
        up0, front0 = rest_axes(base)
        up, front = rest_axes(_turned(base, R))
        assert np.allclose(up, R @ up0, atol=1e-9) and np.allclose(front, R @ front0, atol=1e-9)
        assert abs(rest_height(_turned(base, R)) - rest_height(base)) < 1e-9


def test_unrecognised_rig_stands_as_blender_characters():
    base = load_template().base
    sk = base.skeleton
    anon = Skeleton([f"b{i}" for i in range(sk.num_bones)], sk.parents, sk.heads, sk.tails, sk.frames)
    up, front = rest_axes(Model(base.rest_vertices, base.faces, anon, base.anchor, base.twist_weights,
                                base.swing_weights))
    assert np.allclose(up, [0, 0, 1]) and np.allclose(front, [0, -1, 0])


def test_recording_up_is_the_floor_normal_in_the_tracking_frame():
    R = _rotation([0.3, 1.0, -0.2], 70.0)               # sensor -> tracking frame, any world
    n = np.array([0.0, -0.9, -0.2])                     # a floor seen from a camera tilted down
    assert np.allclose(recording_up(R, n), R @ n / np.linalg.norm(n))
    assert np.allclose(recording_up(R), R @ [0, -1, 0])          # no floor: the image's up
