"""The tracked motion of a depth recording in the scene and on disk.

:func:`build` (main thread, inside ``scene_guard``): the poses become a new action on the rig, one key per
tracked frame on the recording's frames (input frame i on scene frame ``frame_start + i``).  When the
model was a rig in the scene and the solver kept it, the action goes on that rig (its previous action
keeps a fake user); otherwise (the template adapted to the person, a bundle's model) a rig is built from
the tracked model at the solve frame's matrix (the world) and a rig tracked with is hidden.  Either way
it plays over the point cloud.  The action also animates the armature's custom property
``articula_residual_mean_mm`` (the per-frame mean distance of the data to the model), and the report is
stored on the armature.  :func:`look_through` makes the recording's camera the scene camera (and the 3D
views look through it); :func:`save` writes the tracked bundle.
"""
import os

import bpy

from ...solver.errors import ArticulaInputError
from ...solver.formats.bundle import save_bundle
from ...solver.tracking.provenance import track_provenance
from ..rig import actions
from ..tracking.result import bake, check_output_path, tracking_rig
from .report import options_dict, report_document

RESIDUAL_PROPERTIES = (("articula_residual_mean_mm", "mean_mm"),)
TEMPLATE_RIG = "Template Person"       # name of the rig built from the template


def build(context, outcome, name: str = ""):
    """Put the tracked motion of :class:`addon.track_depth.solve.DepthOutcome` ``outcome`` in the scene
    (module docstring).  Returns ``(armature, action, warnings)``.  Call inside ``scene_guard``."""
    mi, cap = outcome.model_input, outcome.captures
    old = bpy.data.objects.get(mi.rig) if mi.rig else None
    if name:
        base = name
    elif old is not None:
        base = actions.adapted_rig_name(old.name)
    else:
        base = TEMPLATE_RIG if mi.model is None else f"{os.path.splitext(mi.label)[0]} tracked"
    arm, names, warnings = tracking_rig(context, outcome.model, old, old is not None and not outcome.new_model,
                                        base, mi.matrix)
    frame0 = cap.frame_start + outcome.first_frame
    action = bake(context, arm, names, outcome, frame0, RESIDUAL_PROPERTIES, report_document(outcome))
    return arm, action, warnings


def look_through(context, camera_name: str) -> bool:
    """Make the object ``camera_name`` (the recording's camera) the scene camera and, in the UI, let the
    3D views look through it.  False when there is no such camera."""
    cam_ob = bpy.data.objects.get(camera_name) if camera_name else None
    if cam_ob is None or cam_ob.type != 'CAMERA':
        return False
    context.scene.camera = cam_ob
    screen = getattr(context, "screen", None)
    for area in (screen.areas if screen is not None else ()):
        if area.type == 'VIEW_3D' and area.spaces.active.region_3d is not None:
            area.spaces.active.region_3d.view_perspective = 'CAMERA'
    return True


def provenance(outcome) -> dict:
    """The tracked bundle's provenance (:func:`solver.tracking.provenance.track_provenance`, the model digest of
    the model given, "" for the template) with the report, the tracker and the poses' coordinates."""
    cap, first = outcome.captures, outcome.first_frame
    prov = track_provenance(outcome.model_input.sha256, cap.object_name or cap.label, cap.total, first,
                            cap.names, options_dict(outcome.options), bool(outcome.result.template),
                            report_document(outcome))
    prov.update(tracker=f"depth {outcome.options.tracker}", coordinates=cap.coordinates,
                template=bool(outcome.result.template), look_ahead=1 if outcome.options.smooth else 0)
    return prov


def save(path: str, outcome) -> None:
    """Write the tracked model (the template adapted, or the given model with its bone names) and one pose
    per tracked frame, in the solve frame's coordinates, with :func:`provenance`."""
    check_output_path(path)
    try:
        save_bundle(path, outcome.model, outcome.poses, provenance(outcome))
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot write the bundle ({exc.strerror or exc})") from None
