"""Bundle files <-> rigs and actions in the scene: what the operators and batch commands call.

Every function validates its whole input (bundle file, names, bone sets) before it creates anything,
and raises :class:`ArticulaInputError` with a message naming the file, object or bone otherwise.
"""
import os

import bpy

from ...solver.formats.bundle import load_bundle, save_bundle
from ...solver.errors import ArticulaInputError
from ...solver.rig.model import Poses
from . import actions
from . import builder as rig_builder
from . import reader as rig_reader
from ..linked import check_editable


def rig_name_for(path: str) -> str:
    """A rig name from a bundle path: the file name without extension."""
    return os.path.splitext(os.path.basename(path))[0] or "Articula"


def load_for_build(path: str, bake: bool = True):
    """Load and fully check the bundle at ``path`` for :func:`build_bundle` (no bpy: safe in a worker
    thread).  Returns the :class:`solver.formats.bundle.Bundle`."""
    bundle = load_bundle(path)
    try:
        rig_builder.check_model(bundle.model, bundle.poses if bake else None)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{path}: {exc}") from exc
    return bundle


def build_bundle(context, bundle, name: str, bake: bool = True, frame_start: int = 1):
    """Build the rig of a checked ``bundle``; bake its poses (if any, and ``bake``) as a new action on
    frames ``frame_start..``.  Returns ``(rig, action or None)``."""
    rig = rig_builder.build_rig(context, bundle.model, name)
    rig.warnings = tuple(bundle.notes) + tuple(rig.warnings)       # e.g. normalised quaternions
    action = None
    if bake and bundle.poses is not None and len(bundle.poses):
        action = actions.write_action(rig.armature, bundle.model.skeleton.names, bundle.poses,
                                      name=f"{name} poses", frame_start=frame_start, scene=context.scene)
    return rig, action


def build_from_bundle(context, path: str, name: str = "", bake: bool = True, frame_start: int = 1):
    """:func:`load_for_build` + :func:`build_bundle` (name defaults to the file name)."""
    bundle = load_for_build(path, bake)
    return build_bundle(context, bundle, name or rig_name_for(path), bake, frame_start)


def poses_for_rig(poses: Poses, bundle_names, rig_names_, path: str = "") -> Poses:
    """``poses`` of bones ``bundle_names`` reordered to the rig's bone order ``rig_names_``."""
    if set(bundle_names) != set(rig_names_):
        missing = sorted(set(rig_names_) - set(bundle_names)) or sorted(set(bundle_names) - set(rig_names_))
        raise ArticulaInputError(f"{path}: the bundle's bones do not match the rig's bones (e.g. {missing[0]!r})")
    if bundle_names[0] != rig_names_[0]:
        raise ArticulaInputError(f"{path}: root bone {bundle_names[0]!r} differs from the rig's root "
                                 f"{rig_names_[0]!r}")
    order = [list(bundle_names).index(n) for n in rig_names_]
    return Poses(poses.rotations[:, order], poses.translations, poses.scales)


def bake_bundle(context, path: str, armature: str = "", nla: bool = False, frame_start: int = 1,
                action_name: str = "", warn=None):
    """Bake the poses of the bundle at ``path`` onto the rig ``armature`` (or the active rig) as a new
    action; returns the action.  ``warn(text)`` receives what loading changed (``Bundle.notes``).  A rig
    linked from another .blend without a library override is refused before anything changes."""
    bundle = load_bundle(path)
    if bundle.poses is None or len(bundle.poses) == 0:
        raise ArticulaInputError(f"{path}: the bundle holds no poses")
    arm = rig_reader.find_armature(armature, context)
    check_editable(arm, "rig")
    names = rig_reader.control_names(arm)
    poses = poses_for_rig(bundle.poses, bundle.model.skeleton.names, names, path)
    for text in bundle.notes if warn is not None else ():
        warn(text)
    return actions.write_action(arm, names, poses, name=action_name or f"{rig_name_for(path)} poses",
                                frame_start=frame_start, nla=nla, scene=context.scene)


def export_bundle(path: str, armature: str = "", action: str = "", poses: str = "ACTIVE", context=None):
    """Write the rig ``armature`` (or the active rig) to a bundle at ``path``.  ``poses``: 'NONE', 'ACTIVE'
    (the active action's poses if there is one) or 'REQUIRED' (fail without an action).  ``action``
    names an action to read instead of the active one.  Returns ``(model, poses or None)``."""
    arm = rig_reader.find_armature(armature, context)
    model = rig_reader.read_model(arm)
    act = None
    if action:
        act = bpy.data.actions.get(action)
        if act is None:
            raise ArticulaInputError(f"no action named {action!r}")
    elif poses != 'NONE' and arm.animation_data is not None:
        act = arm.animation_data.action
    if act is None and poses == 'REQUIRED':
        raise ArticulaInputError(f"armature {arm.name!r} has no active action (name one with action=...)")
    read = rig_reader.read_poses(arm, act) if act is not None and poses != 'NONE' else None
    provenance = {"source": "blender", "armature": arm.name, "action": act.name if act is not None else None,
                  "blender": bpy.app.version_string}
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise ArticulaInputError(f"{path}: folder {directory!r} does not exist")
    save_bundle(path, model, read, provenance)
    return model, read


def scene_counts() -> dict:
    """Numbers of objects, meshes, armatures and actions (for "nothing was created" checks)."""
    return {k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "armatures", "actions")}


__all__ = ["build_from_bundle", "bake_bundle", "export_bundle", "poses_for_rig", "rig_name_for", "scene_counts"]
