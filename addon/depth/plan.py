"""Planning a depth import: the operator's inputs -> an :class:`ImportPlan` (which frames, which camera
intrinsics and depth scale, background and colour frames, where the cache goes), its run in the worker
thread, and the scene objects it builds.  docs/import_depth.md describes inputs and options.

Main thread, except :meth:`ImportPlan.run` (no bpy).  EXR depth and colour frames need Blender's image
loader, so they are read while planning; 16-bit PNG frames are decoded by the run.
"""
from __future__ import annotations

import dataclasses
import os
import time
from typing import Callable

import bpy

from ...solver.depth import camera
from ...solver.depth import frames as dp
from ...solver.depth import recording
from ...solver.errors import ArticulaInputError
from ...solver.formats.point_files import CLOUD_EXTENSIONS
from ..sequences import playback
from ..sequences import points
from . import images

@dataclasses.dataclass
class ImportPlan:
    read: Callable          # read(progress) -> PointSequence; no bpy (runs in the worker thread)
    directory: str          # the folder of frames, absolute
    name: str               # name of the new collection (and its objects)
    cache: str              # cache path as stored on the object (``//``-relative or absolute)
    cache_abs: str          # the same, absolute

    def run(self, progress):
        """Read and process every frame, write the cache; ``seq.timings`` gains ``solver`` and ``cache``
        seconds."""
        t0 = time.perf_counter()
        seq = self.read(progress)
        t1 = time.perf_counter()
        seq.save(self.cache_abs)
        seq.timings.update(solver=t1 - t0, cache=time.perf_counter() - t1)
        return seq

    def build(self, context, seq, frame_start: int, point_radius: float):
        """The collection, camera and point-cloud object (``points.create_sequence_objects``).  On failure
        the scene's camera, frame range and render size are put back and the cache is deleted (the new
        datablocks are removed by the caller's ``jobs.scene_guard``)."""
        scene, render = context.scene, context.scene.render
        settings = (scene.camera, scene.frame_start, scene.frame_end, render.resolution_x, render.resolution_y,
                    render.resolution_percentage, render.pixel_aspect_x, render.pixel_aspect_y)
        try:
            return points.create_sequence_objects(context, self.name, seq, self.cache, self.directory,
                                                  frame_start, point_radius)
        except BaseException:
            if scene.camera is not settings[0] and (settings[0] is None or settings[0].name in bpy.data.objects):
                scene.camera = settings[0]
            (scene.frame_start, scene.frame_end, render.resolution_x, render.resolution_y,
             render.resolution_percentage, render.pixel_aspect_x, render.pixel_aspect_y) = settings[1:]
            points.forget_cache(self.cache_abs)
            if os.path.exists(self.cache_abs):
                os.remove(self.cache_abs)
            raise


def _abs(path: str) -> str:
    return os.path.normpath(bpy.path.abspath(path))


def find_frames(directory: str) -> tuple[list, bool]:
    """``(frame paths, clouds)``: the depth images of the folder, else its point-cloud files."""
    try:
        return recording.list_frames(directory, recording.DEPTH_EXTENSIONS), False
    except ArticulaInputError:
        pass
    try:
        return recording.list_frames(directory, CLOUD_EXTENSIONS), True
    except ArticulaInputError:
        raise ArticulaInputError(
            f"{directory}: no frames found (expected depth images {', '.join(recording.DEPTH_EXTENSIONS)} "
            f"or point clouds {', '.join(CLOUD_EXTENSIONS)})") from None


def resolve_intrinsics(directory: str, intrinsics: str, preset: str, needed: bool):
    """An intrinsics file wins, then a preset (not 'FOLDER'; a name of ``camera.CAMERA_PRESETS``), then the
    folder's ``intrinsics.json``; None when there is none and they are not ``needed`` (point-cloud files)."""
    if intrinsics:
        return recording.camera_file(bpy.path.abspath(intrinsics))[0]
    if preset != 'FOLDER':
        return camera.preset(preset)
    path = os.path.join(directory, "intrinsics.json")
    if os.path.isfile(path):
        return recording.camera_file(path)[0]
    if needed:
        raise ArticulaInputError(f"{directory}: no intrinsics.json; give an intrinsics file or choose a "
                                 f"camera preset ({', '.join(camera.PRESETS)})")
    return None


def depth_frame(path: str) -> recording.DepthFrame:
    """PNG frames are decoded in the worker thread; EXR frames need Blender, so they are read now."""
    if path.lower().endswith(".exr"):
        data = images.load_exr_depth(path)
        return recording.DepthFrame(path, lambda: data, metres=True)
    return recording.png_frames([path])[0]


def colour_frames(color_directory: str, count: int) -> list:
    """One callable per depth frame returning its colour image (read now, by Blender)."""
    cdir = _abs(color_directory)
    cpaths = recording.list_frames(cdir, recording.COLOR_EXTENSIONS)
    if len(cpaths) != count:
        raise ArticulaInputError(f"{cdir}: {len(cpaths)} colour frames for {count} depth frames; "
                                 "the counts must match")
    return [(lambda im=im: im) for im in (images.load_color(p) for p in cpaths)]


def plan_import(directory: str, options: dp.DepthOptions, scale_given: bool = True, intrinsics: str = "",
                preset: str = 'FOLDER', background: str = "", color_directory: str = "", cache_file: str = "",
                name: str = "") -> ImportPlan:
    """Validate the operator's inputs (``operators/import_depth.py``) and prepare the import.
    ``options.depth_scale`` is replaced by the intrinsics' ``depth_unit_m`` unless ``scale_given``."""
    folder = _abs(directory) if directory else ""
    if not folder or not os.path.isdir(folder):
        raise ArticulaInputError(f"{directory or '(no folder given)'}: not a folder")
    paths, clouds = find_frames(folder)
    intr = resolve_intrinsics(folder, intrinsics, preset, needed=not clouds)
    if intr is not None:
        options = recording.unit_options(options, intr, options.depth_scale if scale_given else None)
    options.validate()
    name = name or os.path.basename(folder.rstrip(os.sep)) or "Depth"
    if clouds:
        if color_directory:
            raise ArticulaInputError("colour frames go with depth images; point-cloud files carry their "
                                     "own colours (NPY/XYZ with 6 columns)")
        read = lambda progress: recording.import_clouds(paths, options, progress, intr)  # noqa: E731
    else:
        frames = [depth_frame(p) for p in paths]
        bg = depth_frame(_abs(background)) if background else None
        colors = colour_frames(color_directory, len(paths)) if color_directory else None
        read = lambda progress: recording.import_depth(frames, intr, options, progress, bg, colors)  # noqa: E731
    cache_abs = _abs(cache_file) if cache_file else points.default_cache_path(name)
    cache = cache_file or playback.stored_path(cache_abs)
    return ImportPlan(read, folder, name, cache, cache_abs)
