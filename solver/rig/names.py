"""Names used by Articula rigs: helper-bone prefixes, bone collections, modifiers, widgets.  Plain
strings and string rules (no bpy), shared by the solver's linear-blend layout and the Blender rig.

A rig built from a bundle keeps the bundle's bone names for its control bones (``.L``/``.R`` mirror
suffixes included) and derives every other name from them, so the names alone say what a bone is:
``SW-<c>`` swing helper of joint c (main armature), ``TW-<c>`` twist bone of joint c (twist
armature), ``NEUTRAL`` the static identity bone of the twist armature.
"""
SWING_PREFIX = "SW-"
TWIST_PREFIX = "TW-"
NEUTRAL = "NEUTRAL"

CONTROLS_COLLECTION = "Controls"
HELPERS_COLLECTION = "Helpers"
TWIST_COLLECTION = "Twist"
WIDGETS_COLLECTION = "Articula Widgets"

TWIST_MODIFIER = "Articula Twist"
SWING_MODIFIER = "Articula Swing"

BONE_INDEX_PROP = "articula_index"     # Bone custom property: the bone's index in the bundle
ANCHOR_ATTRIBUTE = "articula_anchor"   # INT point attribute on the rig mesh: the anchor bone index

MAX_NAME_BYTES = 63                   # Blender's limit for bone and vertex-group names


def swing(name: str) -> str:
    return SWING_PREFIX + name


def twist(name: str) -> str:
    return TWIST_PREFIX + name


def side(name: str) -> str:
    """'L', 'R' or '' from a ``.L``/``.R`` (also ``_L``/``-L``) suffix."""
    for s in ("L", "R"):
        if len(name) > 2 and name[-2] in "._-" and name[-1] in (s, s.lower()):
            return s
    return ""


def problem(name: str):
    """Why ``name`` cannot be a control-bone name of a rig, or None when it can."""
    if not name:
        return "is empty"
    if name == NEUTRAL or name.startswith((SWING_PREFIX, TWIST_PREFIX)):
        return f"is reserved for rig helper bones ('{NEUTRAL}', '{SWING_PREFIX}*', '{TWIST_PREFIX}*')"
    if len(swing(name).encode("utf-8")) > MAX_NAME_BYTES:
        return f"is too long (Blender allows {MAX_NAME_BYTES - len(SWING_PREFIX)} bytes for a control bone)"
    return None
