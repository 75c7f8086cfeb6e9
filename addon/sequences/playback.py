"""Playback of sequence objects: the mesh of a scan-sequence or point-cloud-sequence object shows, at
every scene frame, the matching frame of its recording, read from the object's cache file.

One set of persistent handlers serves every kind of sequence object.  A kind (``scans.py``,
``points.py``) registers a :class:`Player` that writes sequence frame k into an object's mesh; this
module decides which objects to update, which frame they show, and keeps their cache paths valid.

* Frame: sequence index ``scene frame - ob.articula.frame_start``, held at the first / last frame
  outside the recording (:func:`frame_index`).  The index a mesh shows is kept in its ID property
  ``articula_frame``, so an unchanged frame costs nothing; being part of the mesh, it is saved, loaded
  and undone together with the geometry it describes.
* Handlers: ``frame_change_pre`` writes the current frame into every sequence object of the scene
  (objects in edit mode and linked meshes are left alone); ``load_post`` drops what the players hold in
  memory and shows the current frame again (the cache may have changed since the file was saved);
  ``undo_post``/``redo_post`` show the current frame (undo restores a mesh as it was when the step was
  pushed); ``save_pre`` re-derives cache paths for the new file location.
* Why ``frame_change_pre``: it runs after ``scene.frame_current`` is set and before the depsgraph
  evaluates the frame, so the new geometry is part of that one evaluation, in the viewport and in every
  frame of an animation render (Blender's own example of a handler that edits a mesh uses it).  Data
  written in ``frame_change_post`` arrives after the frame was evaluated: it needs a second evaluation
  (the points' Geometry Nodes modifier runs twice), and whatever read the first one saw the old frame.
* Cache paths (``ob.articula.cache_file``): ``//``-relative when the cache lies in the .blend's folder
  tree (the project folder can move), else absolute (:func:`stored_path`).

docs/scans.md and docs/import_depth.md describe both kinds of object.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable

import bpy
from bpy.app.handlers import persistent

from ...solver.errors import ArticulaInputError

SHOWN = "articula_frame"   # ID property on the mesh: sequence index it currently shows


@dataclass(frozen=True)
class Player:
    """How one kind of sequence object is played back."""
    label: str           # what a frame is called in messages, e.g. "scan" -> "cannot show scan frame 3"
    show: Callable       # show(ob, k): write sequence frame k into ob.data; raise when it cannot
    forget: Callable     # forget(): drop the loaded caches (a file was loaded, the add-on is disabled)


_players: dict = {}      # ob.articula.kind -> Player
_reported: set = set()   # names of objects whose playback failed (reported once until a file is loaded)


# -- cache files -------------------------------------------------------------------------------------

def safe_name(name: str, fallback: str) -> str:
    """``name`` usable in a file name (other characters than letters, digits, ``-_.`` become ``_``)."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or fallback


def stored_path(abs_path: str, blend_path: str | None = None) -> str:
    """``//relative`` when ``abs_path`` is inside the folder of the .blend (default: the open file),
    else the absolute path."""
    blend_path = bpy.data.filepath if blend_path is None else blend_path
    if blend_path:
        base = os.path.dirname(os.path.abspath(blend_path))
        try:
            rel = os.path.relpath(abs_path, base)
        except ValueError:  # another drive
            return abs_path
        if not rel.startswith(os.pardir):
            return "//" + rel.replace(os.sep, "/")
    return abs_path


def cache_abspath(ob) -> str:
    """Absolute, normalised path of the object's cache ("" when it has none)."""
    return os.path.normpath(bpy.path.abspath(ob.articula.cache_file)) if ob.articula.cache_file else ""


class FileCache:
    """Files loaded once and kept while unchanged (same modification time and size).  ``load(path)``
    reads one; :meth:`get` raises OSError when the file is missing and whatever ``load`` raises."""

    def __init__(self, load: Callable):
        self._load, self._items = load, {}

    def get(self, path: str):
        st = os.stat(path)
        hit = self._items.get(path)
        if hit and hit[0] == (st.st_mtime_ns, st.st_size):
            return hit[1]
        data = self._load(path)
        self._items[path] = ((st.st_mtime_ns, st.st_size), data)
        return data

    def put(self, path: str, data) -> None:
        """Keep ``data`` as what ``path`` (just written) holds."""
        st = os.stat(path)
        self._items[path] = ((st.st_mtime_ns, st.st_size), data)

    def forget(self, path: str | None = None) -> None:
        if path is None:
            self._items.clear()
        else:
            self._items.pop(path, None)


# -- frames --------------------------------------------------------------------------------------------

def frame_index(ob, scene_frame: int) -> int:
    """Sequence index shown at ``scene_frame`` (held at the ends)."""
    n = ob.articula.frame_count
    return min(max(int(scene_frame) - ob.articula.frame_start, 0), max(n - 1, 0))


def sequence_objects(scene) -> list:
    """The objects of ``scene`` that play a sequence now (not in edit mode, mesh not linked)."""
    return [ob for ob in scene.objects
            if ob.type == 'MESH' and ob.articula.kind in _players and ob.articula.cache_file
            and ob.articula.frame_count > 0 and ob.data.library is None and ob.mode != 'EDIT']


def show(ob, scene_frame: int, force: bool = False) -> None:
    """Put the frame for ``scene_frame`` into ``ob``'s mesh (unless it shows it already); raises when the
    cache is unusable."""
    k = frame_index(ob, scene_frame)
    if not force and ob.data.get(SHOWN) == k:
        return
    _players[ob.articula.kind].show(ob, k)
    ob.data[SHOWN] = k


def show_scene(scene, force: bool = False) -> None:
    """Show the current frame on every sequence object of ``scene``.  An object that cannot play keeps
    the frame it shows and is reported once; the others play on."""
    frame = scene.frame_current
    for ob in sequence_objects(scene):
        try:
            show(ob, frame, force)
        except Exception as exc:   # never let one object break playback of the others
            if ob.name not in _reported:
                _reported.add(ob.name)
                why = str(exc) if isinstance(exc, ArticulaInputError) else f"{type(exc).__name__}: {exc}"
                print(f"Articula: {ob.name}: cannot show {_players[ob.articula.kind].label} frame {frame} ({why})")


# -- handlers ------------------------------------------------------------------------------------------

@persistent
def _on_frame_change(scene, depsgraph=None):
    show_scene(scene)


@persistent
def _on_load(*_args):
    _reported.clear()
    for player in _players.values():
        player.forget()
    for scene in bpy.data.scenes:
        show_scene(scene, force=True)


@persistent
def _on_undo_redo(*_args):
    for scene in bpy.data.scenes:
        show_scene(scene)


@persistent
def _on_save_pre(filepath="", *_args):
    """Keep cache paths valid when the .blend is saved somewhere else: re-derive them relative to the
    new file (or absolute when the cache is outside its folder)."""
    if not filepath:
        return
    for ob in bpy.data.objects:
        if ob.type == 'MESH' and ob.articula.kind in _players and ob.articula.cache_file and not ob.library:
            ob.articula.cache_file = stored_path(bpy.path.abspath(ob.articula.cache_file), filepath)


_HANDLERS = (("frame_change_pre", _on_frame_change), ("load_post", _on_load), ("undo_post", _on_undo_redo),
             ("redo_post", _on_undo_redo), ("save_pre", _on_save_pre))


def _remove_handlers():
    """Remove these handlers, also copies left by an earlier load of this module (add-on reload)."""
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        for old in [h for h in handlers if getattr(h, "__name__", "") == fn.__name__
                    and getattr(h, "__module__", "") == fn.__module__]:
            handlers.remove(old)


def add_player(kind: str, player: Player) -> None:
    """Play objects whose ``articula.kind`` is ``kind``; the handlers are installed (once) here."""
    _players[kind] = player
    _remove_handlers()
    for name, fn in _HANDLERS:
        getattr(bpy.app.handlers, name).append(fn)


def remove_player(kind: str) -> None:
    """Stop playing ``kind``; the handlers go with the last player."""
    player = _players.pop(kind, None)
    if player is not None:
        player.forget()
    if not _players:
        _remove_handlers()
        _reported.clear()
