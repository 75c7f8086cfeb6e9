"""The tracking error on the captures: per capture point, its distance (mm) to the tracked model on that
frame, shown as the heat-map attributes of :mod:`addon.learn.heat_map` (``articula_error_mm`` and the
active colour ``articula_error_color``, blue 0 mm to red at the scale) on the capture object's mesh.

A capture object's mesh is rebuilt at every frame change (:mod:`addon.sequences.playback`), so the
errors of all tracked frames live in a file, ``<name>-<id>.track_errors.npz`` (``errors`` float32 mm
concatenated, ``offsets`` (T + 1,), ``first_frame``: input index of tracked frame 0, ``scale`` mm), in
the .blend's cache folder (``<blend name>_articula/``, stored relative) or, for an unsaved file, in the
cache folder's ``track_cache/`` (stored absolute); the object's ID property ``articula_track_errors``
holds its path; saving the .blend carries the file into its cache folder like a playback cache
(:class:`.playback.Reference`: moved from ``track_cache/``, copied from another .blend's folder).  Handlers after the players' (``frame_change_pre``, ``load_post``, ``undo_post``,
``redo_post``) write the shown frame's errors into the mesh; frames outside the tracked range show none.
"""
from __future__ import annotations

import os
import re
import uuid

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ...solver.errors import ArticulaInputError
from .. import preferences
from ..learn import heat_map
from ..sequences import playback

ERRORS_PROPERTY = "articula_track_errors"   # capture object: path of its error file
SHOWN_PROPERTY = "articula_error_frame"     # capture mesh: input frame whose errors the attributes hold
SUFFIX = ".track_errors.npz"
UNSAVED_FOLDER = "track_cache"
SCALE_PERCENTILE = 95.0


def color_scale(errors_mm) -> float:
    """The ramp's top (mm): the 95th percentile of all finite errors, at least 1 mm."""
    finite = [e[np.isfinite(e)] for e in errors_mm]
    values = np.concatenate(finite) if finite else np.zeros(0)
    return max(float(np.percentile(values, SCALE_PERCENTILE)) if len(values) else 0.0, 1.0)


def new_path(name: str, blend_path: str = "") -> str:
    """Absolute path of a new error file (module docstring) for the open .blend or the one about to be
    saved as ``blend_path``; its name is not a playback cache's, so saving never removes it as unused."""
    blend_path = blend_path or bpy.data.filepath
    folder = (playback.blend_cache_folder(blend_path) if blend_path
              else os.path.join(preferences.cache_dir(), UNSAVED_FOLDER))
    return os.path.join(folder, f"{playback.safe_name(name, 'captures')}-{uuid.uuid4().hex[:8]}{SUFFIX}")


def write_errors(ob, errors_mm, first_frame: int, scale: float = None, blend_path: str = "") -> str:
    """Write the per-frame errors of capture object ``ob`` (tracked frames from input frame
    ``first_frame``) to a new file (:func:`new_path`), point ``ob`` at it and show the current frame's
    errors.  Returns the path."""
    path = new_path(ob.name, blend_path)
    errors = [np.asarray(e, np.float32) for e in errors_mm]
    offsets = np.zeros(len(errors) + 1, np.int64)
    np.cumsum([len(e) for e in errors], out=offsets[1:])
    scale = color_scale(errors) if scale is None else float(scale)
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path + ".part", "wb") as fh:
            np.savez(fh, errors=np.concatenate(errors) if errors else np.zeros(0, np.float32), offsets=offsets,
                     first_frame=np.int64(first_frame), scale=np.float64(scale))
        os.replace(path + ".part", path)
    except OSError as exc:
        raise ArticulaInputError(f"cannot write the error colours' file {path}: {exc.strerror or exc}") from None
    ob[ERRORS_PROPERTY] = playback.stored_path(path, blend_path or None)
    if SHOWN_PROPERTY in ob.data:
        del ob.data[SHOWN_PROPERTY]
    show(ob, bpy.context.scene.frame_current, path)     # (stored relative to a .blend not saved yet)
    return path


def _load(path: str) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in ("errors", "offsets", "first_frame", "scale")}


_files = playback.FileCache(_load)


def error_path(ob) -> str:
    """Absolute path of ``ob``'s error file ("" when it has none)."""
    stored = ob.get(ERRORS_PROPERTY, "")
    return os.path.normpath(bpy.path.abspath(stored, library=ob.library)) if stored else ""


def frame_errors(ob, k: int, path: str = ""):
    """``(errors (mm) of input frame k of ob or None outside the tracked range, colour scale)``, read from
    ``path`` (default: :func:`error_path`)."""
    data = _files.get(path or error_path(ob))
    j = k - int(data["first_frame"])
    if not 0 <= j < len(data["offsets"]) - 1:
        return None, float(data["scale"])
    return data["errors"][data["offsets"][j]:data["offsets"][j + 1]], float(data["scale"])


def show(ob, scene_frame: int, path: str = "") -> None:
    """Put the errors of the frame ``ob`` shows at ``scene_frame`` into its mesh (none outside the
    tracked range, or when the frame's point count does not match the mesh); ``path``: the error file
    (default: :func:`error_path`)."""
    me = ob.data
    k = playback.frame_index(ob, scene_frame)
    present = me.attributes.get(heat_map.ERROR_ATTRIBUTE)
    if me.get(SHOWN_PROPERTY) == k and present is not None and len(present.data) == len(me.vertices):
        return
    values, scale = frame_errors(ob, k, path)
    if values is None or len(values) != len(me.vertices):
        for name in (heat_map.ERROR_ATTRIBUTE, heat_map.COLOR_ATTRIBUTE):
            old = me.attributes.get(name)
            if old is not None:
                me.attributes.remove(old)
        me[SHOWN_PROPERTY] = -1
        return
    heat_map.add_heat_map(me, np.where(np.isfinite(values), values, np.inf), scale)
    me[SHOWN_PROPERTY] = k


def show_scene(scene) -> None:
    """Show the errors of the current frame on every capture object of ``scene`` that has them; an object
    whose file is gone keeps playing without colours."""
    for ob in scene.objects:
        if ERRORS_PROPERTY not in ob or ob.type != 'MESH' or ob.library is not None or ob.mode == 'EDIT':
            continue
        try:
            playback.show(ob, scene.frame_current)      # the geometry first (no-op when already shown)
            show(ob, scene.frame_current)
        except (OSError, ValueError, KeyError, ArticulaInputError):
            continue


@persistent
def _on_change(*_args):
    for scene in bpy.data.scenes:
        show_scene(scene)


_HANDLERS = ("frame_change_pre", "load_post", "undo_post", "redo_post")


def _remove_handlers():
    for name in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        for old in [h for h in handlers if getattr(h, "__name__", "") == _on_change.__name__
                    and getattr(h, "__module__", "") == _on_change.__module__]:
            handlers.remove(old)


ERRORS_FILE = playback.Reference(ERRORS_PROPERTY, re.compile(r".+-[0-9a-f]{8}" + re.escape(SUFFIX) + "$"),
                                 UNSAVED_FOLDER)


def register_extra():
    """Install the handlers (after the players', whose modules register first); saving carries the error
    files with the .blend (:class:`.playback.Reference`)."""
    playback.register_reference(ERRORS_FILE)
    _remove_handlers()
    for name in _HANDLERS:
        getattr(bpy.app.handlers, name).append(_on_change)


def unregister_extra():
    _remove_handlers()
    _files.forget()


classes = ()
