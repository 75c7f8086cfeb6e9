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
  pushed); ``save_pre``/``save_post``/``save_post_fail`` carry the caches with the .blend (below).
* Why ``frame_change_pre``: it runs after ``scene.frame_current`` is set and before the depsgraph
  evaluates the frame, so the new geometry is part of that one evaluation, in the viewport and in every
  frame of an animation render (Blender's own example of a handler that edits a mesh uses it).  Data
  written in ``frame_change_post`` arrives after the frame was evaluated: it needs a second evaluation
  (the points' Geometry Nodes modifier runs twice), and whatever read the first one saw the old frame.
* Where caches live (:func:`new_cache_path`): beside a saved .blend in ``<blend name>_articula/``,
  stored ``//``-relative; for an unsaved file in the cache folder (preferences, else $ARTICULA_HOME,
  else ~/.cache/articula) under ``scan_cache/`` or ``point_clouds/``, stored absolute.  Their names
  ``<name>-<8 hex digits><suffix>`` (:data:`CACHE_NAME`) are unique, which is how Articula's own files
  are told from anything else.
* Saving (like Blender's external data; also the files of other modules' :class:`Reference`, e.g. the
  tracking error colours): ``save_pre`` moves the caches of an unsaved file into the new
  ``<blend name>_articula/`` folder and copies those of another .blend's folder there (Save As: the
  original file keeps its own); caches elsewhere (a path the user chose) stay and are stored relative
  when inside the .blend's folder tree, else absolute.  ``save_post`` removes the caches in the saved
  file's folder that neither the file nor its previous version (the ``.blend1``) references, and those
  this session made for the file before its first save that nothing uses, so re-imports leave
  nothing behind; after Save Copy the open file gets its paths back.  A cache that
  cannot be found is also looked for by name in the open file's cache folder (an undo step from before
  a save still names the old place).
* An object whose cache is missing or unusable gets the ID property ``articula_warning`` (the panel
  shows it) and one console line, saying what to do (:func:`cache_advice`: put the named
  ``<blend name>_articula`` folder back beside the .blend, or import again); the property goes when the
  object plays again.

docs/scans.md and docs/import_depth.md describe both kinds of object.
"""
from __future__ import annotations

import os
import re
import shutil
import uuid
from dataclasses import dataclass
from typing import Callable

import bpy
from bpy.app.handlers import persistent

from ...solver.errors import ArticulaInputError
from .. import preferences

SHOWN = "articula_frame"   # ID property on the mesh: sequence index it currently shows
WARNING = "articula_warning"   # ID property on the object: why it cannot play (absent when it plays)
FOLDER_SUFFIX = "_articula"    # <blend name>_articula/: the caches of a saved .blend
UNSAVED_FOLDERS = ("scan_cache", "point_clouds")   # in the cache folder: caches of unsaved files
CACHE_NAME = re.compile(r".+-[0-9a-f]{8}\.(npy|scans|points\.npz)(\.part\d*(\.npz)?)?$")  # Articula's caches


@dataclass(frozen=True)
class Player:
    """How one kind of sequence object is played back."""
    label: str           # what a frame is called in messages, e.g. "scan" -> "cannot show scan frame 3"
    show: Callable       # show(ob, k): write sequence frame k into ob.data; raise when it cannot
    forget: Callable     # forget(): drop the loaded caches (a file was loaded, the add-on is disabled)
    source: str = "source"   # what is imported again to rebuild a cache, e.g. "scans"


@dataclass(frozen=True)
class Reference:
    """Another file that travels with the .blend like a cache: its path is in the object ID property
    ``prop``; it is Articula's when its name matches ``name``; an unsaved file's copy lives in the cache
    folder's ``unsaved_folder``.  Saving carries it as :func:`carry_cache` does a cache; it is never
    removed as unused (it is not a playback cache)."""
    prop: str
    name: re.Pattern
    unsaved_folder: str


def register_reference(ref: Reference) -> None:
    """Let the save handlers carry the files of ``ref`` (idempotent)."""
    if ref not in _references:
        _references.append(ref)


_players: dict = {}      # ob.articula.kind -> Player
_references: list = []   # Reference of other files carried with the .blend
_reported: set = set()   # names of objects whose playback failed (reported once until a file is loaded)
_session_unsaved: set = set()   # caches this session made for an unsaved file (removed at save if unused)


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


def blend_cache_folder(blend_path: str) -> str:
    """The folder of a saved .blend's caches: ``<folder>/<blend name>_articula``."""
    blend_path = os.path.abspath(blend_path)
    stem = os.path.splitext(os.path.basename(blend_path))[0]
    return os.path.join(os.path.dirname(blend_path), stem + FOLDER_SUFFIX)


def new_cache_path(name: str, suffix: str, unsaved_folder: str) -> str:
    """Absolute path for a new cache ``<name>-<8 hex><suffix>``: in the open .blend's cache folder, or
    for an unsaved file in ``<cache folder>/<unsaved_folder>`` (one of :data:`UNSAVED_FOLDERS`)."""
    if bpy.data.filepath:
        folder = blend_cache_folder(bpy.data.filepath)
    else:
        folder = os.path.join(preferences.cache_dir(), unsaved_folder)
    path = os.path.join(folder, f"{safe_name(name, 'cache')}-{uuid.uuid4().hex[:8]}{suffix}")
    if not bpy.data.filepath:
        _session_unsaved.add(path)
    return path


def cache_abspath(ob) -> str:
    """Absolute, normalised path of the object's cache ("" when it has none).  When the stored path does
    not exist, a cache of that name in the open file's cache folder is used if there is one."""
    if not ob.articula.cache_file:
        return ""
    path = os.path.normpath(bpy.path.abspath(ob.articula.cache_file, library=ob.library))
    if not os.path.exists(path) and bpy.data.filepath and ob.library is None:
        moved = os.path.join(blend_cache_folder(bpy.data.filepath), os.path.basename(path))
        if os.path.exists(moved):
            return moved
    return path


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
            why = str(exc) if isinstance(exc, ArticulaInputError) else f"{type(exc).__name__}: {exc}"
            if ob.library is None and ob.get(WARNING) != why:
                ob[WARNING] = why
            if ob.name not in _reported:
                _reported.add(ob.name)
                print(f"Articula: {ob.name}: cannot show {_players[ob.articula.kind].label} frame {frame} ({why})")
        else:
            if WARNING in ob and ob.library is None:
                del ob[WARNING]


def cache_advice(path: str, source: str = "source") -> str:
    """What to do about the cache ``path`` that cannot be read: when it is missing from a .blend's
    ``<blend name>_articula/`` folder, put that folder (named) back beside the .blend; in any case, or
    import ``source`` again (which writes a new cache)."""
    again = f"import the {source} again"
    folder = os.path.dirname(os.path.normpath(path))
    name = os.path.basename(folder)
    if os.path.exists(path) or not path:
        return again
    if name.endswith(FOLDER_SUFFIX):
        parent = os.path.dirname(folder)
        opened = bpy.data.filepath
        blend = (os.path.basename(opened) if opened and os.path.dirname(os.path.abspath(opened)) == parent
                 else name[:-len(FOLDER_SUFFIX)] + ".blend")
        return f"put the folder {name} back beside {blend} (in {parent}), or {again}"
    return f"put {os.path.basename(path)} back in {folder}, or {again}"


def cache_problem(ob) -> str:
    """What keeps ``ob`` from playing and what to do, for the panel: its cache file is missing (checked
    now, with :func:`cache_advice`), else the last playback error (:data:`WARNING`); "" when it plays."""
    path = cache_abspath(ob)
    if path and not os.path.exists(path):
        player = _players.get(ob.articula.kind)
        return f"frame cache missing: {path}; {cache_advice(path, player.source if player else 'source')}"
    return str(ob.get(WARNING, ""))


# -- caches travel with the .blend -------------------------------------------------------------------

_saving: dict = {}       # state between save_pre and save_post / save_post_fail
_on_disk: set = set()    # caches the open file references as saved (its next .blend1 keeps them)


def _sequence_items():
    """(object, absolute cache path) of every local sequence object with a cache."""
    return [(ob, cache_abspath(ob)) for ob in bpy.data.objects
            if ob.type == 'MESH' and ob.articula.kind in _players and ob.articula.cache_file]


def referenced_caches() -> set:
    """Absolute paths of every cache a sequence object of the open file uses."""
    return {path for _ob, path in _sequence_items()}


def is_unsaved_cache(path: str, name=CACHE_NAME, folders=UNSAVED_FOLDERS) -> bool:
    """A cache Articula wrote for an unsaved file (in the cache folder's scan_cache/ or point_clouds/;
    ``name`` and ``folders`` for the files of a :class:`Reference`)."""
    folder = os.path.dirname(os.path.normpath(path))
    return name.match(os.path.basename(path)) is not None and folder in {
        os.path.normpath(os.path.join(preferences.cache_dir(), sub)) for sub in folders}


def is_blend_cache(path: str, name=CACHE_NAME) -> bool:
    """A cache Articula wrote beside a saved .blend (``<blend name>_articula/<name>-<id>...``)."""
    return (name.match(os.path.basename(path)) is not None
            and os.path.basename(os.path.dirname(os.path.normpath(path))).endswith(FOLDER_SUFFIX))


def _copy(src: str, dst: str) -> None:
    tmp = dst + ".part"
    if os.path.isdir(src):
        shutil.copytree(src, tmp)
    else:
        shutil.copy2(src, tmp)
    os.replace(tmp, dst)


def carry_cache(path: str, folder: str, state: dict, name=CACHE_NAME, folders=UNSAVED_FOLDERS) -> str:
    """Where the cache ``path`` lives once the .blend is saved with the cache folder ``folder``: moved
    there when it belongs to an unsaved file, copied there when it belongs to another .blend, else (a
    missing cache, one already there, one the user placed) left where it is.  Records what it did in
    ``state`` ("moved": [(old, new)], "created": [new]) so a failed save can undo it.  ``name``,
    ``folders``: how the files of a :class:`Reference` are recognised."""
    if not os.path.exists(path) or os.path.dirname(path) == os.path.normpath(folder):
        return path
    move = is_unsaved_cache(path, name, folders)
    if not move and not is_blend_cache(path, name):
        return path
    dst = os.path.join(folder, os.path.basename(path))
    if not os.path.exists(dst):          # (a name is unique: one already there is this cache)
        os.makedirs(folder, exist_ok=True)
        if move:
            shutil.move(path, dst)
            state["moved"].append((path, dst))
        else:
            _copy(path, dst)
            state["created"].append(dst)
    elif move:
        remove_path(path)
    return dst


def remove_path(path: str) -> None:
    """Delete a cache file or folder (no error when it is gone already)."""
    if os.path.isdir(path):
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            os.remove(path)
        except OSError:
            pass


def remove_orphans(folder: str, keep: set) -> list:
    """Delete the caches Articula made in ``folder`` (names matching :data:`CACHE_NAME`) that are not in
    ``keep`` (absolute paths); other files are never touched.  Returns the removed paths."""
    if not os.path.isdir(folder):
        return []
    keep = {os.path.normpath(p) for p in keep}
    gone = [os.path.join(folder, n) for n in sorted(os.listdir(folder)) if CACHE_NAME.match(n)
            and os.path.normpath(os.path.join(folder, n)) not in keep]
    for path in gone:
        remove_path(path)
    if not os.listdir(folder):
        os.rmdir(folder)
    return gone


# -- handlers ------------------------------------------------------------------------------------------

@persistent
def _on_frame_change(scene, depsgraph=None):
    show_scene(scene)


@persistent
def _on_load(*_args):
    _reported.clear()
    _on_disk.clear()
    _on_disk.update(referenced_caches())
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
    """Carry every cache to the new file's cache folder (:func:`carry_cache`) and store its path
    relative to the new file; remember the old paths for a Save Copy or a failed save."""
    if not filepath:
        return
    folder = blend_cache_folder(filepath)
    state = {"file": os.path.normpath(os.path.abspath(filepath)), "opened": bpy.data.filepath,
             "paths": {}, "moved": [], "created": []}
    _saving.clear()
    _saving.update(state)
    carried = {}
    for ob, path in _sequence_items():
        if ob.library is not None:
            continue
        if path not in carried:
            try:
                carried[path] = carry_cache(path, folder, state)
            except OSError as exc:
                print(f"Articula: {ob.name}: could not put its cache {path} beside {filepath} ({exc})")
                carried[path] = path
        state["paths"][ob.name] = ob.articula.cache_file
        ob.articula.cache_file = stored_path(carried[path], filepath)
    _carry_references(filepath, folder, state)


def _carry_references(filepath, folder, state) -> None:
    """:func:`_on_save_pre` for the files of every registered :class:`Reference`."""
    state["props"] = []
    for ref in _references:
        for ob in bpy.data.objects:
            stored = ob.get(ref.prop) if ob.library is None else None
            if not isinstance(stored, str) or not stored:
                continue
            path = _reference_abspath(stored, filepath)
            try:
                new = carry_cache(path, folder, state, ref.name, (ref.unsaved_folder,))
            except OSError as exc:
                print(f"Articula: {ob.name}: could not put {path} beside {filepath} ({exc})")
                new = path
            state["props"].append((ob.name, ref.prop, stored))
            ob[ref.prop] = stored_path(new, filepath)


def _reference_abspath(stored: str, filepath: str) -> str:
    """Absolute path of a :class:`Reference`'s stored path while saving as ``filepath``: ``//`` is the open
    file's folder, or, in an unsaved file, the folder of the file being saved (a batch job writes files
    for the .blend it is about to save)."""
    if stored.startswith("//") and not bpy.data.filepath:
        return os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(filepath)), stored[2:]))
    return os.path.normpath(bpy.path.abspath(stored))


def _restore_paths(state) -> None:
    for name, value in state.get("paths", {}).items():
        ob = bpy.data.objects.get(name)
        if ob is not None and ob.library is None:
            ob.articula.cache_file = value
    for name, prop, value in state.get("props", []):
        ob = bpy.data.objects.get(name)
        if ob is not None and ob.library is None:
            ob[prop] = value


@persistent
def _on_save_post(filepath="", *_args):
    """Saved: remove the caches nobody uses any more from the saved file's cache folder (only when the
    open file was saved over itself: a file saved elsewhere may have a .blend1 of its own).  After Save
    Copy the open file keeps its paths, and what was moved for the copy is copied back."""
    state = dict(_saving)
    _saving.clear()
    if not filepath or not state:
        return
    if os.path.normpath(os.path.abspath(bpy.data.filepath or "")) != state["file"]:   # Save Copy
        for old, new in state["moved"]:
            if not os.path.exists(old):
                _copy(new, old)
        _restore_paths(state)
        return
    now = referenced_caches()
    if os.path.normpath(os.path.abspath(state["opened"] or "")) == state["file"]:
        remove_orphans(blend_cache_folder(filepath), now | _on_disk)
    for path in _session_unsaved - now:       # made for this file before it was saved, no longer used
        remove_path(path)
    _session_unsaved.clear()
    _on_disk.clear()
    _on_disk.update(now)


@persistent
def _on_save_fail(filepath="", *_args):
    """The file was not written: undo the moves and copies of ``save_pre`` and the paths."""
    state = dict(_saving)
    _saving.clear()
    for old, new in state.get("moved", []):
        if os.path.exists(new) and not os.path.exists(old):
            shutil.move(new, old)
    for new in state.get("created", []):
        remove_path(new)
    _restore_paths(state)


_HANDLERS = (("frame_change_pre", _on_frame_change), ("load_post", _on_load), ("undo_post", _on_undo_redo),
             ("redo_post", _on_undo_redo), ("save_pre", _on_save_pre), ("save_post", _on_save_post),
             ("save_post_fail", _on_save_fail))


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
