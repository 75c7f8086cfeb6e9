"""Registers every Blender class of the extension, in dependency order.

Each module in ``MODULES`` exposes ``classes`` (a tuple of bpy classes, registered in order)
and may expose ``register_extra()`` / ``unregister_extra()`` for properties, handlers or menus.
"""
import bpy

from .. import operators
from ..solver import parallel
from . import panels, preferences, properties
from .farm import panel_state as farm_state
from .gaze import panel_state as gaze_state
from .retarget import mapping_list
from .sequences import points, scans
from .track import error_colors

# Order matters: property groups before what uses them, operators before the panels that draw their buttons,
# the players (scans, points) before the error colours drawn over what they show.
MODULES = (preferences, properties, mapping_list, gaze_state, farm_state, scans, points, error_colors, operators,
           panels)


def register():
    for mod in MODULES:
        for cls in getattr(mod, "classes", ()):
            bpy.utils.register_class(cls)
        if hasattr(mod, "register_extra"):
            mod.register_extra()


def unregister():
    parallel.shutdown()                       # the solver's idle worker threads
    for mod in reversed(MODULES):
        if hasattr(mod, "unregister_extra"):
            mod.unregister_extra()
        for cls in reversed(getattr(mod, "classes", ())):
            if getattr(cls, "is_registered", False):
                bpy.utils.unregister_class(cls)
