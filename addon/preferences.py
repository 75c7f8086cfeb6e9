"""Add-on preferences: defaults shared by all features (cache folder, worker threads)."""
import os

import bpy

from . import package_name


class ARTICULA_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = package_name()

    cache_dir: bpy.props.StringProperty(
        name="Cache Folder", subtype='DIR_PATH',
        description="Where Articula keeps sample data and intermediate results "
                    "(empty: $ARTICULA_HOME or ~/.cache/articula)",
        default="")
    threads: bpy.props.IntProperty(
        name="Threads", min=0, max=256, default=0,
        description="Worker threads for the solver (0: one per CPU core)")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "cache_dir")
        col.prop(self, "threads")


def get(context=None):
    """The preferences of this add-on, or None when it is not enabled as an add-on (plain register())."""
    context = context or bpy.context
    addon = context.preferences.addons.get(package_name())
    return addon.preferences if addon else None


def cache_dir(context=None) -> str:
    """The effective cache folder (preference, else $ARTICULA_HOME, else ~/.cache/articula)."""
    prefs = get(context)
    if prefs and prefs.cache_dir:
        return bpy.path.abspath(prefs.cache_dir)
    return os.environ.get("ARTICULA_HOME", os.path.join(os.path.expanduser("~"), ".cache", "articula"))


def threads(context=None) -> int:
    """Number of solver threads (>= 1)."""
    prefs = get(context)
    n = prefs.threads if prefs else 0
    return n if n > 0 else (os.cpu_count() or 1)


classes = (ARTICULA_AP_preferences,)
