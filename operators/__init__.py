"""Operators (``bpy.ops.articula.*``).  Thin: parse input, call ``addon`` and ``solver``, report.

Every feature module here exposes ``classes``; they are collected below in registration order.
"""
from . import (bake_poses, bind_scan, build_rig, export_bundle, export_lbs, farm, gaze, import_depth,
               import_scans, learn_rig, retarget, track)

# Registration order.
FEATURES = (build_rig, bake_poses, export_bundle, export_lbs, import_scans, import_depth, learn_rig, track, retarget,
            bind_scan, gaze, farm)

classes = tuple(cls for module in FEATURES for cls in module.classes)
