"""Helpers shared by the batch command modules: calling operators, the scene a command works in, saving
the .blend and ending a command with its summary.

A command that writes a .blend (``--blend`` / ``--out``) runs inside :func:`editing`: an existing file is
opened and added to (the user's objects, actions and settings kept), else the command starts from an
empty scene (no default cube, camera and light).  The importers write their caches as for any unsaved or
opened file, and saving (:func:`save_blend`, Blender's own save: a ``.blend1`` backup of the file it
replaces, as the preferences' save versions say) carries them beside the .blend with relative paths
(``addon/sequences/playback.py``).  A command that fails saves nothing: an existing file keeps its bytes,
no new file is made, and the caches the command wrote are removed (:mod:`.outputs`, around every
command, removes any other output a failed command started: bundle, report, temporary files).  So does a command given no
``--blend`` (also with ``--open file.blend``: the opened file is never saved over unasked); its last
line says so (:data:`NOT_SAVED`).
"""
import contextlib
import io
import json
import os
import re
import sys

import bpy

from ...solver.errors import ArticulaInputError
from ...solver.formats.atomic import written_through
from .. import console
from ..sequences import playback

NOT_SAVED = "not saved: give --blend FILE to keep it"


def write_json(path: str, doc: dict) -> None:
    """Write ``doc`` as indented JSON to ``path`` through a temporary file (no half-written report, no
    temporary file left; a path that cannot be written is an input error)."""
    with written_through(path, path + ".tmp", "the report") as tmp, open(tmp, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1)


def _without_report(printed: str, report: str) -> str:
    """``printed`` without the lines of ``report`` (the error Blender printed and also raised)."""
    lines = {line for line in report.splitlines() if line.strip()}
    return "".join(line for line in printed.splitlines(keepends=True) if line.rstrip("\n") not in lines)


def call_operator(op, **props) -> None:
    """Run ``bpy.ops.<x>(**props)``; an operator's ERROR report (bad input) becomes ``ArticulaInputError``
    with the operator's message.  Blender prints an operator's reports to stdout as well as raising them;
    the error is left out there, so the command prints it once (``main``: ``articula <cmd>: error: ...``)."""
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            op(**props)
    except RuntimeError as exc:
        sys.stdout.write(_without_report(printed.getvalue(), str(exc)))
        raise ArticulaInputError(str(exc).replace("Error: ", "").strip()) from None
    sys.stdout.write(printed.getvalue())


def check_blend_output(path: str) -> None:
    """Refuse, before any work, a .blend output that exists but is not a writable file."""
    if not path:
        return
    blend = os.path.abspath(path)
    if os.path.isdir(blend):
        raise ArticulaInputError(f"{path}: is a folder, not a .blend file")
    if os.path.exists(blend) and not os.access(blend, os.R_OK | os.W_OK):
        raise ArticulaInputError(f"{path}: the .blend file is not readable and writable")
    parent = os.path.dirname(blend)
    while not os.path.isdir(parent) and os.path.dirname(parent) != parent:
        parent = os.path.dirname(parent)
    if not os.access(parent, os.W_OK):
        raise ArticulaInputError(f"{path}: cannot write in {parent!r}")


def open_blend(path: str) -> None:
    """Open an existing .blend (a clear error when it is missing or not a .blend file)."""
    blend = os.path.abspath(path)
    if not os.path.isfile(blend):
        raise ArticulaInputError(f"{path}: no such .blend file")
    try:
        with console.without_lines(console.READ_BLEND):
            call_operator(bpy.ops.wm.open_mainfile, filepath=blend)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{path}: cannot open it as a .blend file ({exc})") from None


def start_scene(blend: str = "") -> None:
    """The scene a command works in: ``blend`` opened when that file exists (the command adds to it);
    else the file opened before the command (``--open``, ``blender -b file.blend``), else an empty
    scene."""
    check_blend_output(blend)
    if blend and os.path.exists(os.path.abspath(blend)):
        open_blend(blend)
    elif not bpy.data.filepath:
        bpy.ops.wm.read_homefile(use_empty=True)


@contextlib.contextmanager
def editing(blend: str = ""):
    """Run a command's body in :func:`start_scene`'s scene; when it raises, or when there is no ``blend``
    to save to, the caches it made are deleted (nothing is saved, so nothing references them)."""
    start_scene(blend)
    before = playback.referenced_caches()
    try:
        yield
    except BaseException:
        _remove_new_caches(before)
        raise
    if not blend:
        _remove_new_caches(before)


def _remove_new_caches(before: set) -> None:
    """Delete the caches Articula wrote since ``before`` (:func:`playback.referenced_caches`), and a
    ``<name>_articula`` folder they leave empty; caches at a path the user chose stay."""
    for path in playback.referenced_caches() - before:
        if playback.is_unsaved_cache(path) or playback.is_blend_cache(path):
            playback.remove_path(path)
            folder = os.path.dirname(path)
            if playback.is_blend_cache(path) and os.path.isdir(folder) and not os.listdir(folder):
                os.rmdir(folder)      # the cache folder this command made


def save_blend(path: str) -> None:
    """Save the scene as ``path`` (its folder is made when missing): over the opened file with Blender's
    save (its previous version kept as ``.blend1``), else as a new file; the caches go beside it."""
    blend = os.path.abspath(path)
    folder = os.path.dirname(blend)
    made = not os.path.isdir(folder)
    os.makedirs(folder, exist_ok=True)
    try:
        if bpy.data.filepath and os.path.normpath(bpy.data.filepath) == os.path.normpath(blend):
            call_operator(bpy.ops.wm.save_mainfile)
        else:
            call_operator(bpy.ops.wm.save_as_mainfile, filepath=blend)
    except ArticulaInputError as exc:
        if made and not os.listdir(folder):
            os.rmdir(folder)
        raise ArticulaInputError(f"{path}: could not save ({exc})") from None


def save_blend_as(path: str) -> None:
    """:func:`save_blend` to ``path`` whose folder must exist."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ArticulaInputError(f"{path}: folder {folder!r} does not exist")
    save_blend(path)


def finish(summary: str, blend: str = "", scene: bool = True) -> int:
    """End a command: print its one-line ``summary``; with ``blend``, save the scene there
    (:func:`save_blend`) and say so, else, for a command that makes a scene (``scene``; False for one
    that only writes other files), say that nothing was saved and how to keep it (:data:`NOT_SAVED`,
    the last line; :func:`editing` then removes the caches).  Returns exit code 0."""
    print(summary)
    if blend:
        save_blend(blend)
        print(f"saved {blend}")
    elif scene:
        opened = f" ({os.path.basename(bpy.data.filepath)} is unchanged)" if bpy.data.filepath else ""
        print(NOT_SAVED + opened)
    return 0


def allow_axis_values(parser) -> None:
    """Let a command's options take signed axis values such as ``-Y`` (``--facing -Y``, ``--up -Z``): argparse
    would take them for options, as it would ``-1`` if it did not know negative numbers."""
    parser._negative_number_matcher = re.compile(r"^-\d+$|^-\d*\.\d+$|^-[XYZxyz]$")
