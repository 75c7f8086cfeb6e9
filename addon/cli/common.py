"""Helpers shared by the batch command modules: calling operators and saving the .blend."""
import os

import bpy

from ...solver.errors import ArticulaInputError


def call_operator(op, **props) -> None:
    """Run ``bpy.ops.articula.<x>(**props)``; an operator's ERROR report (bad input) becomes
    ``ArticulaInputError`` with the operator's message."""
    try:
        op(**props)
    except RuntimeError as exc:
        raise ArticulaInputError(str(exc).replace("Error: ", "").strip()) from None


def save_blend_first(path: str) -> str:
    """Save the current (empty or opened) file at ``path`` before importing, so caches written by the
    import go next to it and are referenced relative to it.  Returns the absolute path."""
    blend = os.path.abspath(path)
    os.makedirs(os.path.dirname(blend), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    return blend


def save_blend_again() -> None:
    """Save the current file once more, without leaving a ``.blend1`` of the copy saved just before."""
    prefs = bpy.context.preferences.filepaths
    versions, prefs.save_version = prefs.save_version, 0
    try:
        bpy.ops.wm.save_mainfile()
    finally:
        prefs.save_version = versions
    print(f"saved {bpy.data.filepath}")
