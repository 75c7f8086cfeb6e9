"""What depth tracking reads: the model (an Articula rig, a bundle file, or none: the built-in template
body) and the recording (an imported depth object in the scene, or a folder of depth frames).

Coordinates.  The solver tracks in one frame, the *solve frame*, in which the poses come out: for a rig in
the scene its object space (the rig keeps its ``matrix_world`` and plays over the points), else the
Blender world (the rig built from a bundle or the template stands at the origin).  An imported depth
object holds sensor-frame points (OpenCV axes: +X right, +Y down, +Z forward) and its ``matrix_world``
maps them into the world (``addon.sequences.points``: the object is parented to the recording's camera
with the local rotation diag(1, -1, -1), or placed by ``world_from_sensor`` without a camera), so the
camera the solver sees through is ``inv(solve matrix) @ object matrix_world``.  A folder (batch command)
is tracked as written: in the world of ``intrinsics.json``'s ``cam_to_world``, else the camera frame.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ...solver.depth import camera as cam
from ...solver.depth.recording import DEPTH_EXTENSIONS, list_frames
from ...solver.errors import ArticulaInputError
from ...solver.tracking.provenance import model_digest
from ...solver.track_depth.source import DepthRecording, PointsRecording
from ..depth import images
from ..rig import bundle_io, reader
from ..sequences import playback, points
from ..tracking.inputs import ModelInput, parse_frames

METHOD_ITEMS = (('AUTO', "Auto", "The depth tracker for a depth recording (a point cloud imported with its camera), "
                                 "the capture tracker for scans and other point clouds"),
                ('CAPTURES', "Captures", "The capture tracker (scans or point clouds seen from all sides; "
                                         "needs a rig or a bundle)"),
                ('DEPTH', "Depth Camera", "The depth-camera tracker (one depth camera's view; without a rig "
                                          "or bundle the built-in template body adapts to the person)"))
TEMPLATE_LABEL = "the built-in template body"
RIGID_TOLERANCE = 1e-4     # largest |R^T R - I| of a camera placement taken as rigid (no scale in it)


@dataclass
class DepthCaptures:
    """A depth recording to track: ``recording`` (:class:`solver.track_depth.source.DepthRecording` or
    ``PointsRecording``, already cut to the tracked frames), ``label`` for messages, ``total`` frames of
    the input, ``first`` (the input frame of the recording's frame 0), the scene frame of input frame 0,
    the depth object and its camera object ("" for a folder) and what the poses' coordinates are."""
    recording: object
    label: str
    total: int
    first: int = 0
    frame_start: int = 1
    object_name: str = ""
    camera_name: str = ""
    coordinates: str = ""

    @property
    def names(self) -> list:
        return list(self.recording.names)


# -- which tracker ---------------------------------------------------------------------------------------

def is_depth_recording(ob) -> bool:
    """True for a point-cloud object whose cache holds the depth camera's intrinsics (imported from depth
    frames, or point clouds given intrinsics): one camera's view."""
    if ob.articula.kind != 'POINT_CLOUD_SEQUENCE':
        return False
    return points.load_sequence(playback.cache_abspath(ob), ob.name).intrinsics is not None


def uses_depth_tracker(ob, method: str) -> bool:
    """Whether ``articula.track`` runs the depth tracker on capture object ``ob`` (``method``: one of
    :data:`METHOD_ITEMS`' identifiers)."""
    if method == 'CAPTURES':
        return False
    if method == 'DEPTH':
        if ob.articula.kind != 'POINT_CLOUD_SEQUENCE':
            raise ArticulaInputError(f"{ob.name!r} is a scan sequence; the depth-camera tracker needs a depth "
                                     f"recording (Import › Depth Recording…)")
        return True
    return is_depth_recording(ob)


# -- the model ---------------------------------------------------------------------------------------------

def template_input() -> ModelInput:
    """No model: the solver tracks its built-in template body, adapted to the person, in the world."""
    return ModelInput(None, None, TEMPLATE_LABEL, "", "", np.eye(4))


def selected_rig(context, name: str = ""):
    """The rig ``name`` (or a part of it), else the active or a selected Articula rig, else None."""
    if name:
        return reader.find_armature(name, context)
    for ob in [context.active_object, *getattr(context, "selected_objects", [])]:
        if ob is not None and ob.articula.kind in ('RIG_ARMATURE', 'RIG_MESH', 'TWIST_ARMATURE'):
            return reader.find_armature(ob.name, context)
    return None


def find_model(context, rig: str = "", bundle: str = "") -> ModelInput:
    """The model to track with: the bundle file ``bundle`` (absolute path; solve frame = world), else the
    rig ``rig`` or the active / a selected rig (solve frame = its object space), else the template."""
    if bundle:
        loaded = bundle_io.load_for_build(bundle, bake=False)
        return ModelInput(loaded.model, None, os.path.basename(bundle), model_digest(loaded.model), "", np.eye(4))
    arm = selected_rig(context, rig)
    if arm is None:
        return template_input()
    model = reader.read_model(arm)
    return ModelInput(model, None, f"rig {arm.name!r}", model_digest(model), arm.name,
                      np.array(arm.matrix_world, np.float64))


# -- the recording -----------------------------------------------------------------------------------------

def frame_slice(first: int, last: int, count: int, frame_start: int):
    """Scene frames ``first..last`` of an object whose input frame 0 is on scene frame ``frame_start`` ->
    ``slice`` of input frames; raises when they are not all frames of the object."""
    a, b = first - frame_start, last - frame_start
    if not 0 <= a <= b < count:
        raise ArticulaInputError(f"Frame Range {first}..{last} lies outside the captures' frames "
                                 f"{frame_start}..{frame_start + count - 1}")
    return slice(a, b + 1)


def _check_rigid(m: np.ndarray, what: str) -> None:
    r = m[:3, :3]
    if np.abs(r.T @ r - np.eye(3)).max() > RIGID_TOLERANCE or np.linalg.det(r) < 0:
        raise ArticulaInputError(f"{what} is scaled, sheared or mirrored; the depth tracker works in metres: give "
                                 f"the point cloud, its camera and the rig scale 1 (Object › Apply › Scale on the rig)")


def camera_object(ob):
    """The recording's camera object: the depth object's parent when that is a camera, else None."""
    parent = ob.parent
    return parent if parent is not None and parent.type == 'CAMERA' else None


def recording_from_object(ob, matrix, frames: slice | None = None) -> DepthCaptures:
    """The depth object ``ob`` (main thread: resolves its cache) tracked in the solve frame whose world
    matrix is ``matrix`` (4, 4); ``frames``: a slice of its input frames (None: all)."""
    seq = points.load_sequence(playback.cache_abspath(ob), ob.name)
    if seq.frame_count < 1:
        raise ArticulaInputError(f"{ob.name!r} holds no frames")
    to_solve = np.linalg.inv(np.asarray(matrix, np.float64)) @ np.array(ob.matrix_world, np.float64)
    _check_rigid(to_solve, f"{ob.name!r} as seen from the rig")
    recording = PointsRecording(seq, cam_to_world=to_solve, frames=frames)
    first = 0 if frames is None else range(seq.frame_count)[frames].start
    cam_ob = camera_object(ob)
    where = "the world" if np.allclose(matrix, np.eye(4)) else "the rig's object space"
    return DepthCaptures(recording, repr(ob.name), seq.frame_count, first, int(ob.articula.frame_start), ob.name,
                         cam_ob.name if cam_ob is not None else "", f"Blender: {where}")


def recording_from_folder(folder: str, camera: str | None = None, frames: str | None = None,
                          flag: str = "--camera") -> DepthCaptures:
    """The depth frames of ``folder`` (16-bit PNG, or EXR in metres read by Blender) with its
    ``intrinsics.json``, else the camera preset ``camera`` (:data:`solver.depth.camera.PRESETS`);
    ``frames``: "A:B" (input frames A..B-1)."""
    folder = os.path.abspath(folder)
    paths = list_frames(folder, DEPTH_EXTENSIONS)
    has_intrinsics = os.path.isfile(os.path.join(folder, "intrinsics.json"))
    if not has_intrinsics and not camera:
        raise ArticulaInputError(f"{folder}: no intrinsics.json; give the camera with {flag} "
                                 f"({', '.join(cam.PRESETS)})")
    span = None
    if frames is not None:
        a, b = parse_frames(frames, len(paths))
        span = slice(a, b)
    recording = DepthRecording.from_folder(folder, preset=None if has_intrinsics else camera, frames=span,
                                           read_exr=images.load_exr_depth)
    coordinates = ("world: intrinsics.json's cam_to_world" if recording.world
                   else "camera: OpenCV axes (+X right, +Y down, +Z forward)")
    return DepthCaptures(recording, folder, len(paths), 0 if span is None else span.start, 1, "", "", coordinates)

