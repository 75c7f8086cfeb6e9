"""What both trackers put in the scene the same way: the rig that plays the tracked motion
(:func:`tracking_rig`), the action baked on it with the per-frame residual curves and the report
(:func:`bake`), and the early refusal of an output file in a missing folder (:func:`check_output_path`)."""
import json
import os

import bpy
import numpy as np
from mathutils import Matrix

from ...solver.errors import ArticulaInputError
from .. import compat
from ..rig import actions
from ..rig import builder as rig_builder
from ..rig import reader
from .inputs import TRACKED_ACTION

REPORT_PROPERTY = "articula_track_report"      # armature ID property: the report (JSON)
RESIDUAL_GROUP = "Tracking residual"


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


def add_residual_curves(arm, action, result, frame0: int, properties) -> None:
    """Key the per-frame residuals (``properties``: (custom property, key of ``result.frames``' rows), mm)
    as the armature's custom properties on frames ``frame0 ..``; frames without a value (skipped) get no
    key."""
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


def residuals_mm(result, key: str = "median_mm") -> np.ndarray:
    """Per tracked frame the report's ``key`` (mm), NaN where a frame has none (skipped)."""
    out = []
    for row in result.frames:
        value = row.get(key) if isinstance(row, dict) else None
        out.append(float(value) if isinstance(value, (int, float)) and value is not None else np.nan)
    return np.array(out, np.float64)


def check_output_path(path: str) -> None:
    """Refuse an output file whose folder does not exist (before the run, not after it)."""
    if path:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise ArticulaInputError(f"{path}: folder {folder!r} does not exist")
