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
import json
import os

import bpy
import numpy as np
from mathutils import Matrix

from ...solver.errors import ArticulaInputError
from ...solver.formats.bundle import save_bundle
from ...solver.track.merge import track_provenance
from .. import compat
from ..rig import actions
from ..rig import builder as rig_builder
from ..rig import reader
from . import error_colors
from .inputs import TRACKED_ACTION, TRAINING_ACTION
from .report import REPORT_PROPERTY, options_dict, report_document, residuals_mm

RESIDUAL_PROPERTIES = (("articula_residual_median_mm", "median_mm"), ("articula_residual_mean_mm", "mean_mm"))
RESIDUAL_GROUP = "Tracking residual"


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


def tracking_rig(context, model, old, keep: bool, base: str, matrix):
    """The rig that plays the tracked motion: ``old`` itself when ``keep`` (its control bones must still
    be the model's), else a rig built from ``model`` named after ``base`` at ``matrix`` (4, 4), ``old``
    hidden.  Returns ``(armature, bone names, warnings)``."""
    if keep:
        names = reader.control_names(old)
        if names != list(model.skeleton.names):
            raise ArticulaInputError(f"rig {old.name!r}: its bones changed while tracking; track again")
        return old, names, []
    rig = rig_builder.build_rig(context, model, base)
    arm = rig.armature
    arm.matrix_world = Matrix(np.asarray(matrix, np.float64).tolist())
    if old is not None:
        hide_rig(old)
    return arm, list(model.skeleton.names), list(rig.warnings)


def bake(context, arm, names, outcome, frame0: int, residual_properties, report: dict):
    """The tracked poses as the action "<rig> tracked <recording>" (:func:`actions.tracked_action_name`)
    from scene frame ``frame0``, marked as tracked, with the residual curves and the ``report`` (JSON) on
    the armature."""
    cap = outcome.captures
    name = actions.tracked_action_name(arm.name, cap.object_name or cap.label)
    action = actions.write_action(arm, names, outcome.poses, name=name, frame_start=frame0, scene=context.scene)
    action[TRACKED_ACTION] = True
    add_residual_curves(arm, action, outcome.result, frame0, residual_properties)
    arm[REPORT_PROPERTY] = json.dumps(report)
    return action


def hide_rig(arm) -> None:
    """Hide the objects of the rig ``arm`` in the view layer (the adapted rig replaces it)."""
    for ob in (arm, *arm.children_recursive):
        try:
            ob.hide_set(True)
        except RuntimeError:        # not in the view layer
            pass


def _channels(arm, action):
    """Where ``action``'s F-curves for ``arm`` go (its slot's channelbag on 4.4+, the action before)."""
    if not compat.has_slotted_actions():
        return action
    slot = arm.animation_data.action_slot
    for layer in action.layers:
        for strip in layer.strips:
            return strip.channelbag(slot, ensure=True)
    raise ArticulaInputError(f"action {action.name!r} has no keyframe strip")


def add_residual_curves(arm, action, result, frame0: int, properties=RESIDUAL_PROPERTIES) -> None:
    """Key the per-frame residuals (``properties``: (custom property, key of ``result.frames``' rows);
    by default the median and mean scan-to-model distance, mm) as the armature's custom properties on
    frames ``frame0 ..``; frames without a value (skipped) get no key."""
    bag = _channels(arm, action)
    constant = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["CONSTANT"].value
    for prop, key in properties:
        values = residuals_mm(result, key)
        arm[prop] = 0.0
        ok = np.flatnonzero(np.isfinite(values))
        fc = compat.fcurve_new(bag, f'["{prop}"]', 0, RESIDUAL_GROUP)
        if not len(ok):
            continue
        co = np.column_stack([frame0 + ok, values[ok]]).astype(np.float32)
        fc.keyframe_points.add(len(ok))
        fc.keyframe_points.foreach_set("co", co.ravel())
        fc.keyframe_points.foreach_set("interpolation", np.full(len(ok), constant, np.int32))
        fc.update()


def check_output_path(path: str) -> None:
    """Refuse an output file whose folder does not exist (before the run, not after it)."""
    if path:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise ArticulaInputError(f"{path}: folder {folder!r} does not exist")


def provenance(outcome) -> dict:
    """The tracked bundle's provenance (:func:`solver.track.merge.track_provenance`) with the report."""
    cap, first = outcome.captures, outcome.first_frame
    return track_provenance(outcome.model_input.sha256, cap.object_name or cap.label, len(cap.names), first,
                            cap.names[first:first + len(outcome.poses)], options_dict(outcome.options),
                            outcome.result.adapted, report_document(outcome))


def save(path: str, outcome) -> None:
    """Write the tracked (adapted) model and one pose per tracked frame, in the solve frame's
    coordinates (the capture files' own for the batch command), with :func:`provenance`."""
    check_output_path(path)
    try:
        save_bundle(path, outcome.model, outcome.poses, provenance(outcome))
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot write the bundle ({exc.strerror or exc})") from None
