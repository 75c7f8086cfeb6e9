"""The one place where differences between Blender 4.2 LTS ... 5.2 LTS are handled.

Callers ask questions ("are actions slotted?") instead of comparing version numbers themselves.
"""
import bpy

VERSION = bpy.app.version  # (major, minor, patch)


def at_least(major: int, minor: int = 0) -> bool:
    """True when the running Blender is ``major.minor`` or newer."""
    return VERSION[:2] >= (major, minor)


def has_slotted_actions() -> bool:
    """Slotted (layered) actions: 4.4+.  From 5.0 on ``Action.fcurves`` no longer exists."""
    return at_least(4, 4)


def has_legacy_action_fcurves() -> bool:
    """``Action.fcurves`` exists (Blender < 5.0)."""
    return not at_least(5, 0)
