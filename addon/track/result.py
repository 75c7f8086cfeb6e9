"""The tracked motion in the scene and on disk.

:func:`build` (main thread, inside ``scene_guard``): the poses become a new action on the rig, one key per
tracked frame on the captures' frames (input frame i on scene frame ``frame_start + i``), so the rig plays
over the captures.  Without adaptation the action goes on the rig that was tracked with (its previous
action keeps a fake user); when the model was adapted, or the model came from a bundle, a rig is built
from the tracked model (as ``articula.learn_rig`` builds its result) at the solve frame's matrix, and a
rig tracked with is hidden.  The action also animates the armature's custom properties
``articula_residual_median_mm`` and ``articula_residual_mean_mm`` (the per-frame residual curves, in the
Graph Editor), the report is stored on the armature and the capture object gets its error colours
(:mod:`.error_colors`).  :func:`save` writes the tracked bundle.
"""
import os

import bpy

from ...solver.errors import ArticulaInputError
from ...solver.formats.bundle import save_bundle
from ...solver.tracking.provenance import track_provenance
from ..rig import actions
from ..tracking.inputs import TRAINING_ACTION
from ..tracking.result import bake, check_output_path, tracking_rig
from . import error_colors
from .report import options_dict, report_document

RESIDUAL_PROPERTIES = (("articula_residual_median_mm", "median_mm"), ("articula_residual_mean_mm", "mean_mm"))


def build(context, outcome, name: str = "", blend_path: str = ""):
    """Put the tracked motion of :class:`addon.track.solve.TrackOutcome` ``outcome`` in the scene (module
    docstring); ``blend_path``: the .blend it will be saved as (where the error colours' file goes), when
    not the open file.  Returns ``(armature, action, warnings)``.  Call inside ``scene_guard``."""
    mi, cap = outcome.model_input, outcome.captures
    old = bpy.data.objects.get(mi.rig) if mi.rig else None
    keep = old is not None and not outcome.result.adapted
    base = name or (actions.adapted_rig_name(old.name) if old is not None
                    else f"{os.path.splitext(mi.label)[0]} tracked")
    arm, names, warnings = tracking_rig(context, outcome.model, old, keep, base, mi.matrix)
    if keep and mi.training_action and not arm.get(TRAINING_ACTION):
        arm[TRAINING_ACTION] = mi.training_action
    frame0 = cap.frame_start + outcome.first_frame
    action = bake(context, arm, names, outcome, frame0, RESIDUAL_PROPERTIES, report_document(outcome))
    if cap.object_name and outcome.point_errors_mm is not None:
        error_colors.write_errors(bpy.data.objects[cap.object_name], outcome.point_errors_mm, outcome.first_frame,
                                  blend_path=blend_path)
    return arm, action, warnings


def provenance(outcome) -> dict:
    """The tracked bundle's provenance (:func:`solver.tracking.provenance.track_provenance`) with the report."""
    cap, first = outcome.captures, outcome.first_frame
    return track_provenance(outcome.model_input.sha256, cap.object_name or cap.label, len(cap.names), first,
                            cap.names[first:first + len(outcome.poses)], options_dict(outcome.options),
                            outcome.result.adapted, report_document(outcome))


def save(path: str, outcome) -> None:
    """Write the tracked (adapted) model and one pose per tracked frame, in the solve frame's
    coordinates (the capture files' own for the batch command), with :func:`provenance` and pass 1's state
    per frame (``pass1_*`` arrays: ``track --start-pose`` of one of its frames goes on from it)."""
    check_output_path(path)
    try:
        save_bundle(path, outcome.model, outcome.poses, provenance(outcome), getattr(outcome.result, "pass1", None))
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot write the bundle ({exc.strerror or exc})") from None
