"""Helpers shared by the batch command modules: calling operators, saving the .blend and ending a
command with its summary."""
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


def save_blend_as(path: str) -> None:
    """Save the scene as ``path`` (a new file, or over the opened one); its folder must exist."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ArticulaInputError(f"{path}: folder {folder!r} does not exist")
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path))


def finish(summary: str, blend: str = "", saved_first: bool = False) -> int:
    """End a command: print its one-line ``summary``; with ``blend``, save the scene and say where —
    in place when :func:`save_blend_first` already saved it at that path (``saved_first``: prints the
    absolute path), else with :func:`save_blend_as` (prints ``blend`` as given).  Returns exit code 0."""
    print(summary)
    if blend and saved_first:
        save_blend_again()
    elif blend:
        save_blend_as(blend)
        print(f"saved {blend}")
    return 0
