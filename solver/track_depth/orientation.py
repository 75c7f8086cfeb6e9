"""Which way is up: the model's rest axes and the recording's up direction.

A model's rest pose may stand along any axis (Blender characters along +Z, an OBJ or glTF body along +Y),
and a recording's world may be Z-up, Y-up, tilted or the camera's own frame; neither is assumed.  The
model's up and front come from its bones' roles (:mod:`solver.roles`): up from the hips joint to the head
(or neck), left from the right thigh joint to the left one, front = left x up.  The recording's up comes
from its floor plane when one was found, else from the camera (its image's up, -Y in OpenCV axes): depth
cameras film people upright.  The start pose is then checked to stand (:mod:`.standing`).
"""
from __future__ import annotations

import numpy as np

from ..roles import role_bones

BLENDER_UP = np.array([0.0, 0.0, 1.0])
BLENDER_FRONT = np.array([0.0, -1.0, 0.0])   # Blender and MakeHuman characters face -Y
CAMERA_UP = np.array([0.0, -1.0, 0.0])       # OpenCV camera axes: +Y points down the image


def _unit(v):
    return v / max(float(np.linalg.norm(v)), 1e-12)


def rest_axes(model) -> tuple:
    """``(up, front)`` unit (3,) vectors of ``model``'s rest body in model coordinates, from its bone
    roles; a rig whose roles are not recognised is taken to stand as Blender's characters do (+Z up,
    facing -Y)."""
    sk = model.skeleton
    roles = role_bones(sk.names)
    top = next((r for r in ("head", "neck", "chest") if r in roles), None)
    if top is None or "hips" not in roles or "thigh.L" not in roles or "thigh.R" not in roles:
        return BLENDER_UP.copy(), BLENDER_FRONT.copy()
    h = sk.heads
    up = _unit(h[roles[top]] - h[roles["hips"]])
    left = h[roles["thigh.L"]] - h[roles["thigh.R"]]
    left = left - (left @ up) * up
    if np.linalg.norm(left) < 1e-9:
        return BLENDER_UP.copy(), BLENDER_FRONT.copy()
    return up, _unit(np.cross(_unit(left), up))


def rest_height(model) -> float:
    """The rest body's extent along its up axis (metres)."""
    up, _ = rest_axes(model)
    return float(np.ptp(model.rest_vertices @ up))


def recording_up(camera_rotation: np.ndarray, floor_normal=None) -> np.ndarray:
    """Unit (3,) up in the tracking frame: ``floor_normal`` (sensor frame, pointing to the camera side)
    turned by ``camera_rotation`` (3, 3, sensor to tracking frame) when a floor was found, else the
    camera's image up."""
    n = CAMERA_UP if floor_normal is None else np.asarray(floor_normal, dtype=np.float64)
    return _unit(np.asarray(camera_rotation, dtype=np.float64) @ n)


def view_frame(camera_rotation: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(3, 3) columns (right, forward, up) in the tracking frame: ``up`` and the camera's viewing direction
    made level.  Directions sampled in this frame (the limb search's) are the same relative to the person
    and the camera in every world."""
    up = _unit(np.asarray(up, dtype=np.float64))
    forward = np.asarray(camera_rotation, dtype=np.float64)[:, 2]
    forward = forward - (forward @ up) * up
    if np.linalg.norm(forward) < 1e-6:                 # looking straight down: the image's up is forward
        forward = np.asarray(camera_rotation, dtype=np.float64) @ CAMERA_UP
        forward = forward - (forward @ up) * up
    forward = _unit(forward)
    return np.stack([np.cross(forward, up), forward, up], axis=1)
