"""Operators (``bpy.ops.articula.*``).  Thin: parse input, call ``addon`` and ``solver``, report.

Every feature module here exposes ``classes``; they are collected below in registration order.
"""
import importlib

FEATURES = (
    "build_rig",
    "bake_poses",
    "export_bundle",
    "export_lbs",
    "import_scans",
    "import_depth",
    "learn_rig",
)

classes = tuple(cls for name in FEATURES
                for cls in importlib.import_module(f".{name}", __package__).classes)
