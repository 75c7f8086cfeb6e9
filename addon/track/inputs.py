"""What tracking reads: the model (an Articula rig in the scene or a bundle file) and the captures (a
scan-sequence or point-cloud object, or capture files), checked before the solver runs.

Coordinates.  The solver works in one frame, the *solve frame*, in which the model is given: the rig's
object space (its ``matrix_world`` places it in the scene), or for a bundle the captures' own space
(a scan-sequence object's file coordinates, which is what a bundle learned from those files uses) or
the world (a point-cloud object, whose own space is the depth sensor's).  Capture points are mapped
into it by ``inv(solve matrix) @ capture object matrix``, so the object transform and axis conversion
of the captures are honoured; the tracked rig then stands at the solve matrix and plays over them.
Files (batch command) are used as written: the solve frame is the files' coordinates.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import bpy
import numpy as np

from ...solver.depth.camera import Intrinsics
from ...solver.errors import ArticulaInputError
from ...solver.formats.mesh_files import MESH_EXTENSIONS
from ...solver.formats.polymesh import PolyMesh
from ...solver.formats.scan_files import list_scan_files, natural_sorted
from ...solver.rig.model import Model
from ...solver.track.captures import POINT_EXTENSIONS, CaptureSource, read_capture_file
from ...solver.track.trail import resume_at
from ...solver.tracking.provenance import model_digest
from ..rig import bundle_io, reader
from ..sequences import playback, points, scans
from ..tracking.inputs import TRACKED_ACTION, TRAINING_ACTION, ModelInput

CAPTURE_KINDS = ('SCAN_SEQUENCE', 'POINT_CLOUD_SEQUENCE')
@dataclass
class CaptureInput:
    """Captures to track: ``reader(i) -> (points (N, 3) in the solve frame, triangles (G, 3) or None)``
    for input frame i, in the vertex order of the capture object's mesh (so per-point errors colour it),
    one name per frame, per-frame cameras (or None), the scene frame of input frame 0, a label for
    messages, and the capture object ("" for files)."""
    reader: object
    names: list
    cameras: list = None
    frame_start: int = 1
    label: str = ""
    object_name: str = ""
    kind: str = "FILES"
    to_solve: np.ndarray = field(default_factory=lambda: np.eye(4))

    def source(self, max_points: int) -> CaptureSource:
        """The solver's lazy :class:`CaptureSource` of these frames."""
        return CaptureSource(self.names, self.reader, self.cameras, max_points)


# -- the model ------------------------------------------------------------------------------------------

def model_from_rig(arm) -> ModelInput:
    """The model of Articula rig ``arm`` (object space) with its training poses: those of the action it
    was trained on (the active one unless tracking made it, then the one tracking first replaced)."""
    model = reader.read_model(arm)
    action = _training_action(arm)
    poses = reader.read_poses(arm, action) if action is not None else None
    return ModelInput(model, poses, f"rig {arm.name!r}", model_digest(model), arm.name,
                      np.array(arm.matrix_world, np.float64), action.name if action is not None else "")


def bundle_start_pose(spec: str, model: Model, flag: str = "--start-pose") -> tuple:
    """``(pose (one frame), label, resume)`` from ``spec`` = ``BUNDLE.npz[:K]``: pose K (default 0) of a
    bundle whose bones are ``model``'s (names and order), in the captures' coordinates like the tracked
    output; ``resume``: pass 1's state there when the bundle was tracked with ``model`` (else None)."""
    path, k = spec, 0
    head, sep, tail = spec.rpartition(":")
    if sep and tail.isdigit() and head:
        path, k = head, int(tail)
    try:
        bundle = bundle_io.load_for_build(os.path.abspath(path), bake=False)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{flag}: {exc}") from None
    names = list(bundle.model.skeleton.names)
    if names != list(model.skeleton.names):
        raise ArticulaInputError(f"{flag}: {path} has other bones than the model ({len(names)} vs "
                                 f"{model.skeleton.num_bones}; first: {names[:3]})")
    count = 0 if bundle.poses is None else len(bundle.poses)
    if not 0 <= k < count:
        raise ArticulaInputError(f"{flag}: {path} has {count} pose(s); pose {k} asked for (0-based)")
    return bundle.poses.take([k]), f"pose {k} of {os.path.basename(path)}", _resume(bundle, k, model, path, flag)


def _resume(bundle, k: int, model: Model, path: str, flag: str):
    """Pass 1's state after pose ``k`` of a tracked bundle made with ``model`` (:mod:`solver.track.trail`),
    or None (another model, not tracked, or that frame lost in pass 1)."""
    prov = bundle.provenance
    if prov.get("source") != "track" or prov.get("model_sha256") != model_digest(model):
        return None
    try:
        resume = resume_at(bundle.extra, k, int(prov.get("first_frame", 0)), model.skeleton.num_bones)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{flag}: {path}: {exc}") from None
    names = prov.get("frame_names") or []
    if resume is not None and k < len(names):
        resume.frame_name = str(names[k])
    return resume


def _training_action(arm):
    """The action holding ``arm``'s training poses, or None."""
    active = arm.animation_data.action if arm.animation_data else None
    if active is not None and not active.get(TRACKED_ACTION):
        return active
    name = arm.get(TRAINING_ACTION, "")
    return bpy.data.actions.get(name) if name else None


def model_from_bundle(path: str) -> ModelInput:
    """The model and poses of the bundle at ``path`` (checked as the rig builder needs it)."""
    bundle = bundle_io.load_for_build(path, bake=False)
    poses = bundle.poses if bundle.poses is not None and len(bundle.poses) else None
    return ModelInput(bundle.model, poses, os.path.basename(path), model_digest(bundle.model))


def find_rig(context, name: str = ""):
    """The rig to track with: the object ``name`` (or a part of a rig), else the active object or a
    selected one that is part of an Articula rig."""
    if name:
        return reader.find_armature(name, context)
    for ob in [context.active_object, *getattr(context, "selected_objects", [])]:
        if ob is not None and ob.articula.kind in ('RIG_ARMATURE', 'RIG_MESH', 'TWIST_ARMATURE'):
            return reader.find_armature(ob.name, context)
    raise ArticulaInputError("no rig: make an Articula rig active (or select it with the captures), or give a "
                             "bundle file")


# -- captures in the scene -------------------------------------------------------------------------------

def find_captures(context, name: str = ""):
    """The capture object: ``name``, else the one scan-sequence or point-cloud object among the active and
    selected objects."""
    if name:
        ob = bpy.data.objects.get(name)
        if ob is None:
            raise ArticulaInputError(f"captures: no object named {name!r}")
        if ob.type != 'MESH' or ob.articula.kind not in CAPTURE_KINDS:
            raise ArticulaInputError(f"{name!r} is not a scan-sequence or point-cloud object; import the captures "
                                     f"first (Import › Scans… or Depth Recording…)")
        return ob
    found = []
    for ob in [context.active_object, *getattr(context, "selected_objects", [])]:
        if ob is not None and ob.type == 'MESH' and ob.articula.kind in CAPTURE_KINDS and ob not in found:
            found.append(ob)
    if not found:
        raise ArticulaInputError("no captures: select a scan-sequence or point-cloud object (Import › Scans… or "
                                 "Depth Recording…) together with the rig")
    if len(found) > 1:
        raise ArticulaInputError(f"several capture objects are selected ({', '.join(o.name for o in found[:3])}); "
                                 f"select one or name it")
    return found[0]


def solve_matrix(model_input: ModelInput, ob) -> np.ndarray:
    """(4, 4) solve frame -> world (module docstring)."""
    if model_input.matrix is not None:
        return model_input.matrix
    if ob.articula.kind == 'SCAN_SEQUENCE':
        return np.array(ob.matrix_world, np.float64)
    return np.eye(4)


def captures_from_object(ob, matrix) -> CaptureInput:
    """The frames of capture object ``ob`` (main thread: resolves its cache) mapped into the solve frame
    whose world matrix is ``matrix``; the frames are read from the cache when the solver asks."""
    to_solve = np.linalg.inv(np.asarray(matrix, np.float64)) @ np.array(ob.matrix_world, np.float64)
    if ob.articula.frame_count < 1:
        raise ArticulaInputError(f"{ob.name!r} holds no frames")
    if ob.articula.kind == 'SCAN_SEQUENCE':
        reader_, cameras, names = _scan_reader(ob, to_solve)
    else:
        reader_, cameras, names = _points_reader(ob, to_solve)
    return CaptureInput(reader_, names, cameras, int(ob.articula.frame_start), repr(ob.name), ob.name,
                        ob.articula.kind, to_solve)


def _apply(m, p):
    return np.asarray(p, np.float64) @ m[:3, :3].T + m[:3, 3]


def _scan_reader(ob, m):
    data = scans.cache_data(ob)                      # names the object when its cache is missing
    n = ob.articula.frame_count
    if ob.articula.registered:
        if data.ndim != 3 or data.shape[1] != len(ob.data.vertices):
            raise ArticulaInputError(f"{ob.name}: its frame cache does not match the mesh; import the scans again")
        tris = scans.read_polymesh(ob.data).triangles()

        def read(i):
            return _apply(m, data[i]), tris
    else:
        offsets = [data[k] for k in ("vertex_offsets", "face_offsets", "corner_offsets")]
        if len(offsets[0]) - 1 < n:
            raise ArticulaInputError(f"{ob.name}: its frame cache has {len(offsets[0]) - 1} frames, not {n}; "
                                     f"import the scans again")

        def read(i):
            (v0, v1), (f0, f1), (c0, c1) = (o[i:i + 2] for o in offsets)
            mesh = PolyMesh(np.array(data["positions"][v0:v1], np.float64), np.array(data["face_sizes"][f0:f1]),
                            np.array(data["corner_verts"][c0:c1]))
            return _apply(m, mesh.vertices), (mesh.triangles() if len(mesh.face_sizes) else None)
    return read, None, [f"{ob.name} {k + 1}" for k in range(n)]


def _points_reader(ob, m):
    seq = points.load_sequence(playback.cache_abspath(ob), ob.name)
    cameras = None
    if seq.intrinsics is not None:          # the sensor frame is the object's own space (OpenCV axes)
        w, h, fx, fy, cx, cy = seq.intrinsics
        one = [(m.copy(), Intrinsics(int(w), int(h), float(fx), float(fy), float(cx), float(cy)))]
        cameras = [one] * seq.frame_count

    def read(i):
        return _apply(m, seq.points[seq.frame(i)]), None
    names = list(seq.frame_names) if seq.frame_names is not None and len(seq.frame_names) else []
    return read, cameras, names or [f"{ob.name} {k + 1}" for k in range(seq.frame_count)]


# -- capture files (batch) --------------------------------------------------------------------------------

def capture_paths(items) -> list:
    """Capture files from ``items``: one folder (every mesh or point file in it, natural order) or files
    (natural order, one folder)."""
    items = [os.path.abspath(p) for p in items]
    if len(items) == 1 and os.path.isdir(items[0]):
        return list_scan_files(items[0], MESH_EXTENSIONS + POINT_EXTENSIONS)
    for p in items:
        if not os.path.isfile(p):
            raise ArticulaInputError(f"{p}: file or folder not found")
    if len({os.path.dirname(p) for p in items}) > 1:
        raise ArticulaInputError("give capture files from one folder (or the folder itself)")
    return natural_sorted(items)


def captures_from_files(paths) -> CaptureInput:
    """Capture files as written (solve frame = file coordinates)."""
    paths = list(paths)
    folder = os.path.dirname(paths[0]) if paths else ""
    return CaptureInput(lambda i: read_capture_file(paths[i]), [os.path.basename(p) for p in paths], None, 1,
                        folder if len(paths) > 1 else paths[0])
