"""Where the frames of an import come from: :func:`plan_import` turns the operator's inputs into a
reader, and the Blender-side sources live here: an Alembic file (through Blender's importer), a mesh
object's shape keys, or a mesh object's animation.  Main thread only (the plan's ``read`` runs in the
worker and does not touch bpy).  All positions are in world
space (the object transform applied), so the new scan-sequence object sits at the origin and overlaps
its source.

Alembic: ``wm.alembic_import`` imports into a temporary collection; every frame is sampled by setting
the cache file's frame override and updating the depsgraph (the scene's current frame, and with it the
rest of the user's scene, is not touched); afterwards every datablock the import created is removed and
the scene's frame range, active collection, selection and active object are restored.  Blender's
importer converts Alembic's Y-up to Blender's Z-up: a point (x, y, z) of the file becomes (x, -z, y),
then the object's (converted) transform applies.

Axes of mesh files and point caches (``solver.formats.axes``): the frames are kept in the files'
coordinates and the new object's matrix carries the conversion to Blender's Z up (OBJ: forward -Z, up Y
by default; PLY/STL/OFF/MDD/PC2: as written), as Blender's own importers place them.
"""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass, field
from typing import Callable

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.formats import axes as file_axes
from ...solver.formats.mesh_files import MESH_EXTENSIONS, read_mesh
from ...solver.formats.pointcache import CACHE_EXTENSIONS, read_point_cache
from ...solver.formats.scan_files import (ScanSequence, SequenceAssembler, list_scan_files, natural_sorted,
                                    read_scan_files, sequence_from_cache)
from . import scans

_ID_COLLECTIONS = ("objects", "meshes", "cache_files", "materials", "collections", "curves", "pointclouds",
                   "cameras", "lights", "images", "actions", "node_groups", "armatures")


@contextlib.contextmanager
def temporary_import(context):
    """Run an importer inside: new objects land in a temporary collection, and on exit every new
    datablock is removed and frame range / active collection / selection / active object restored."""
    before = {n: {i.as_pointer() for i in getattr(bpy.data, n)} for n in _ID_COLLECTIONS if hasattr(bpy.data, n)}
    scene, view_layer = context.scene, context.view_layer
    saved = (scene.frame_start, scene.frame_end, scene.frame_current, view_layer.active_layer_collection.collection,
             [o.name for o in view_layer.objects.selected], view_layer.objects.active)
    tmp = bpy.data.collections.new("articula-import-tmp")
    scene.collection.children.link(tmp)
    view_layer.active_layer_collection = view_layer.layer_collection.children[tmp.name]
    try:
        yield tmp
    finally:
        bpy.data.batch_remove([i for name in before for i in getattr(bpy.data, name)
                               if i.as_pointer() not in before[name]])
        start, end, current, active_coll, selected, active = saved
        scene.frame_start, scene.frame_end = start, end
        if scene.frame_current != current:
            scene.frame_current = current
        layer = _find_layer_collection(view_layer.layer_collection, active_coll)
        if layer is not None:
            view_layer.active_layer_collection = layer
        for ob in view_layer.objects:
            ob.select_set(ob.name in selected)
        view_layer.objects.active = active


def _find_layer_collection(layer, collection):
    if layer.collection == collection:
        return layer
    for child in layer.children:
        found = _find_layer_collection(child, collection)
        if found is not None:
            return found
    return None


def _evaluated_polymesh(ob, depsgraph):
    ev = ob.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        return scans.read_polymesh(me, ev.matrix_world)
    finally:
        ev.to_mesh_clear()


def sample_alembic(context, path: str, require_registered: bool = False) -> ScanSequence:
    """Every frame of the mesh in an Alembic file (the largest one when there are several)."""
    if not os.path.isfile(path):
        raise ArticulaInputError(f"{path}: file not found")
    name = os.path.basename(path)
    with temporary_import(context) as tmp:
        try:
            result = bpy.ops.wm.alembic_import(filepath=path, as_background_job=False, set_frame_range=True)
        except RuntimeError as exc:
            raise ArticulaInputError(f"{path}: Blender could not import this Alembic file ({exc})") from None
        meshes = [o for o in tmp.all_objects if o.type == 'MESH']
        if result != {'FINISHED'} or not meshes:
            raise ArticulaInputError(f"{path}: no mesh found in this Alembic file")
        ob = max(meshes, key=lambda o: len(o.data.vertices))
        first, last = context.scene.frame_start, context.scene.frame_end
        caches = [m.cache_file for o in meshes for m in o.modifiers
                  if m.type == 'MESH_SEQUENCE_CACHE' and m.cache_file] + \
                 [c.cache_file for o in meshes for c in o.constraints
                  if c.type == 'TRANSFORM_CACHE' and c.cache_file]
        for cf in set(caches):
            cf.override_frame = True
        depsgraph = context.evaluated_depsgraph_get()
        asm = SequenceAssembler(require_registered)
        for f in range(first, last + 1):
            for cf in set(caches):
                cf.frame = f
            depsgraph.update()
            mesh = _evaluated_polymesh(ob, depsgraph)
            _check_finite(mesh.vertices, f"{name} frame {f}")
            asm.add(mesh, f"{name} frame {f}")
    return asm.result()


def _check_finite(vertices, where):
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise ArticulaInputError(f"{where}: vertex {int(np.flatnonzero(bad)[0])} has a non-finite coordinate")


def source_mesh_object(name: str):
    ob = bpy.data.objects.get(name)
    if ob is None:
        raise ArticulaInputError(f"object {name!r} not found")
    if ob.type != 'MESH':
        raise ArticulaInputError(f"object {name!r} is a {ob.type.lower()}, not a mesh")
    return ob


def object_has_animation(ob) -> bool:
    keys = ob.data.shape_keys
    return bool((ob.animation_data and ob.animation_data.action)
                or (keys and keys.animation_data and keys.animation_data.action)
                or (ob.parent and object_has_animation(ob.parent))
                or any(m.type == 'ARMATURE' and m.object and m.object.animation_data
                       and m.object.animation_data.action for m in ob.modifiers))


def sample_shape_keys(ob) -> ScanSequence:
    """One frame per shape key (the basis first), world space."""
    keys = ob.data.shape_keys
    if keys is None or not keys.key_blocks:
        raise ArticulaInputError(f"{ob.name}: has no shape keys")
    topo = scans.read_polymesh(ob.data)
    m = np.array(ob.matrix_world, np.float64)
    frames = np.empty((len(keys.key_blocks), len(topo.vertices), 3), np.float32)
    buf = np.empty(3 * len(topo.vertices), np.float32)
    for k, kb in enumerate(keys.key_blocks):
        kb.data.foreach_get("co", buf)
        frames[k] = buf.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        _check_finite(frames[k], f"{ob.name} shape key {kb.name!r}")
    topo = type(topo)(frames[0].astype(np.float64), topo.face_sizes, topo.corner_verts)
    return ScanSequence([f"{ob.name}:{kb.name}" for kb in keys.key_blocks], topo, frames)


def sample_animation(context, ob, first: int, last: int, require_registered: bool = False) -> ScanSequence:
    """The evaluated (deformed) mesh of ``ob`` at every frame ``first..last`` (world space).  The scene
    frame is stepped and restored afterwards."""
    if last < first:
        raise ArticulaInputError(f"{ob.name}: empty frame range {first}..{last}")
    scene = context.scene
    current = scene.frame_current
    asm = SequenceAssembler(require_registered)
    try:
        for f in range(first, last + 1):
            scene.frame_set(f)
            mesh = _evaluated_polymesh(ob, context.evaluated_depsgraph_get())
            _check_finite(mesh.vertices, f"{ob.name} frame {f}")
            asm.add(mesh, f"{ob.name} frame {f}")
    finally:
        scene.frame_set(current)
    return asm.result()


# -- the operator's inputs -> a reader ---------------------------------------------------------------


@dataclass
class ImportPlan:
    read: Callable          # read(progress) -> ScanSequence; no bpy (runs in the worker thread)
    name: str               # name for the new object
    source: str             # what was imported, for ``ob.articula.source``
    matrix: object = None   # (4, 4) object matrix of the new object (the files' axis conversion) or None
    caches: dict = field(init=False)   # registered? -> path of the new cache (bpy: chosen on the main thread)

    def __post_init__(self):
        self.caches = {registered: scans.new_cache_path(self.name, registered) for registered in (True, False)}

    def run(self, progress) -> tuple:
        """Read the frames and write their cache (no bpy: the worker thread); ``(sequence, cache path)``."""
        seq = self.read(progress)
        progress(0.95, "writing frame cache")
        path = self.caches[seq.registered]
        scans.write_cache(path, seq)
        return seq, path

    def create_object(self, context, seq, path: str, frame_start: int):
        """The scan-sequence object (``scans.create_object``); the cache is deleted if that fails."""
        try:
            return scans.create_object(context, self.name, seq, path, frame_start, self.source, self.matrix)
        except BaseException:
            scans.remove_cache(path)
            raise


def resolve_files(filepath: str, directory: str, names) -> tuple:
    """(kind, paths) with kind 'MESHES', 'ALEMBIC', 'CACHE', or None when no file input was given."""
    directory = bpy.path.abspath(directory) if directory else ""
    names = [n for n in names if n]
    filepath = bpy.path.abspath(filepath) if filepath else ""
    if names:
        paths = [os.path.join(directory, n) for n in natural_sorted(names)]
    elif filepath and not os.path.isdir(filepath):
        if not os.path.exists(filepath):
            raise ArticulaInputError(f"{filepath}: file or folder not found")
        paths = [filepath]
    elif filepath or directory:
        return 'MESHES', list_scan_files(filepath or directory)
    else:
        return None, []
    exts = {os.path.splitext(p)[1].lower() for p in paths}
    if exts <= set(MESH_EXTENSIONS):
        if len(exts) > 1:
            raise ArticulaInputError(f"mixed file types ({', '.join(sorted(exts))}); pick one format")
        return 'MESHES', paths
    if len(paths) == 1 and exts == {".abc"}:
        return 'ALEMBIC', paths
    if len(paths) == 1 and exts <= set(CACHE_EXTENSIONS):
        return 'CACHE', paths
    raise ArticulaInputError(f"cannot import {', '.join(os.path.basename(p) for p in paths[:3])}: pick mesh "
                             f"files ({', '.join(MESH_EXTENSIONS)}), a folder of them, one .abc, or one "
                             f".mdd/.pc2 with a base mesh")


def plan_import(context, filepath="", directory="", names=(), source_object="", base_mesh="", name="",
                require_registered=False, object_frames='AUTO', source_range=(0, 0),
                axes=(file_axes.AUTO, file_axes.AUTO)) -> ImportPlan:
    """Validate the inputs (see ``operators/import_scans.py``) and prepare the reading.  Blender data
    (Alembic, objects) is sampled here; files are read later by ``plan.read`` in the worker.
    ``axes``: (forward, up) of the files (``AUTO``: the format's convention)."""
    picked_file = any(names) or (filepath and not os.path.isdir(bpy.path.abspath(filepath)))
    if source_object and not picked_file:   # e.g. confirmed in the file browser without picking a file
        kind, paths = None, []
    else:
        kind, paths = resolve_files(filepath, directory, names)
    if kind is None and not source_object:
        raise ArticulaInputError("nothing to import: give files, a folder, or a source object")
    matrix = _axis_matrix(kind, paths[0] if paths else "", axes)      # bad axes refused before any reading
    plan = _plan_source(context, kind, paths, source_object, base_mesh, name, require_registered, object_frames,
                        source_range)
    plan.matrix = matrix
    return plan


def _axis_matrix(kind: str, path: str, axes) -> np.ndarray:
    """The new object's matrix for files of ``kind`` read with ``axes`` (None: identity)."""
    explicit = any(file_axes.parse_axis(a) != file_axes.AUTO for a in axes)
    if kind is None:
        if explicit:
            raise ArticulaInputError("Forward/Up axes apply to files; a mesh object's frames are taken in world "
                                     "space (set both axes to Format Default)")
        return None
    ext = os.path.splitext(path)[1].lower()
    m = file_axes.conversion(ext, *axes)
    if kind == 'ALEMBIC':      # Blender's importer already applied the format's own conversion
        m = m @ file_axes.conversion(ext).T
    return None if np.allclose(m, np.eye(4)) else m


def _plan_source(context, kind, paths, source_object, base_mesh, name, require_registered, object_frames,
                 source_range) -> ImportPlan:
    if kind == 'MESHES':
        if len(paths) == 1:
            default, source = os.path.splitext(os.path.basename(paths[0]))[0], paths[0]
        else:
            source = os.path.dirname(os.path.abspath(paths[0]))
            default = os.path.basename(source) or "scans"
        return ImportPlan(lambda progress: read_scan_files(paths, progress, require_registered),
                          name or default, source)
    if kind == 'CACHE':
        return _plan_point_cache(context, paths[0], base_mesh, source_object, name)
    if kind == 'ALEMBIC':
        seq = sample_alembic(context, paths[0], require_registered)
        return ImportPlan(lambda progress: seq, name or os.path.splitext(os.path.basename(paths[0]))[0], paths[0])
    ob = source_mesh_object(source_object)
    mode = object_frames
    if mode == 'AUTO':
        mode = 'ANIMATION' if object_has_animation(ob) else 'SHAPE_KEYS'
    if mode == 'SHAPE_KEYS':
        seq = sample_shape_keys(ob)
    else:
        first = source_range[0] or context.scene.frame_start
        last = source_range[1] or context.scene.frame_end
        seq = sample_animation(context, ob, first, last, require_registered)
    what = "shape keys" if mode == 'SHAPE_KEYS' else "animation"
    return ImportPlan(lambda progress: seq, name or f"{ob.name}_scans", f"object {ob.name} ({what})")


def _plan_point_cache(context, cache: str, base_mesh: str, source_object: str, name: str) -> ImportPlan:
    cache_name = os.path.basename(cache)
    base_file = bpy.path.abspath(base_mesh) if base_mesh else ""
    base = None
    if not base_file:
        base_ob = source_mesh_object(source_object) if source_object else context.active_object
        if base_ob is None or base_ob.type != 'MESH':
            raise ArticulaInputError(f"{cache_name}: a point cache has no faces; give a base mesh file or "
                                     f"select the mesh it belongs to")
        base = (scans.read_polymesh(base_ob.data), base_ob.name)

    def read(progress):
        progress(0.1, f"reading {cache_name}")
        frames = read_point_cache(cache)
        mesh, mesh_name = base or (read_mesh(base_file), os.path.basename(base_file))
        return sequence_from_cache(frames, mesh, cache_name, mesh_name)

    return ImportPlan(read, name or os.path.splitext(cache_name)[0], cache)
