"""Registers every Blender class of the extension, in dependency order.

Each module listed in ``MODULES`` exposes ``classes`` (a tuple of bpy classes, registered in order)
and may expose ``register_extra()`` / ``unregister_extra()`` for properties, handlers or menus.
"""
import importlib

import bpy

from ..solver import parallel

# Relative to the extension package.  Order matters: property groups before what uses them,
# operators before the panels that draw their buttons.
MODULES = (
    ".addon.preferences",
    ".addon.properties",
    ".addon.scan_sequence",
    ".addon.point_cloud_sequence",
    ".operators",
    ".addon.panels",
)

_PKG = __package__.rpartition(".")[0]  # the extension package, e.g. "bl_ext.user_default.articula"


def _modules():
    return [importlib.import_module(name, _PKG) for name in MODULES]


def register():
    for mod in _modules():
        for cls in getattr(mod, "classes", ()):
            bpy.utils.register_class(cls)
        if hasattr(mod, "register_extra"):
            mod.register_extra()


def unregister():
    parallel.shutdown()                       # the solver's idle worker threads
    for mod in reversed(_modules()):
        if hasattr(mod, "unregister_extra"):
            mod.unregister_extra()
        for cls in reversed(getattr(mod, "classes", ())):
            if getattr(cls, "is_registered", False):
                bpy.utils.unregister_class(cls)
