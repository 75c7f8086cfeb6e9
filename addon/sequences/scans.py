"""The scan-sequence object: a mesh object that plays a sequence of scans back frame by frame.

Storage
    All frames live in one cache file, written once at import; ``ob.articula.cache_file`` holds its path
    (relative to the .blend when the file sits in the .blend's folder tree, else absolute).  It is put in
    ``<blend folder>/<blend name>_articula/`` when the .blend is saved, else in the preferences' cache
    folder under ``scan_cache/``, and travels with the .blend when it is saved (:mod:`.playback`).

    * registered sequences: ``<name>-<id>.npy``, one ``(N, V, 3)`` float32 array, memory-mapped, so a
      frame change reads only that frame.  The object's mesh carries the faces (first frame's topology).
    * unregistered sequences (topology changes between frames): a folder ``<name>-<id>.scans/`` of
      memory-mapped ``.npy`` arrays (concatenated positions, face sizes and corner vertices, and their
      per-frame offsets); a frame change rebuilds the mesh geometry from one frame's slices.
      Chosen over one mesh datablock per frame (swapped into the object) because the .blend stays
      small and both kinds share one storage path; the price is a slower frame change.

Playback (:mod:`.playback`: handlers, frame index, cache paths)
    A registered frame is written through the position attribute (the fast path); an unregistered one
    rebuilds the mesh's geometry.  docs/scans.md has the measured costs.

:func:`scan_frames` hands all frames to the solver as one array (no source files re-read).
"""
from __future__ import annotations

import os
import shutil

import bpy
import numpy as np
from mathutils import Matrix

from ...solver.errors import ArticulaInputError
from ...solver.formats.polymesh import PolyMesh
from ...solver.formats.scan_files import ScanSequence
from ..scene import frames, mesh_io
from . import playback

SOURCE = "scans"   # what is imported again to rebuild a cache (messages)

# -- Blender mesh <-> PolyMesh ----------------------------------------------------------------------


def set_geometry(me: bpy.types.Mesh, vertices, face_sizes, corner_verts) -> None:
    """Replace ``me``'s geometry with polygons (``face_sizes`` (F,), ``corner_verts`` (C,))."""
    v = np.ascontiguousarray(vertices, np.float32).reshape(-1)
    sizes = np.asarray(face_sizes, np.int32)
    starts = np.zeros(len(sizes), np.int32)
    np.cumsum(sizes[:-1], out=starts[1:])
    me.clear_geometry()
    if not len(v):
        me.update()
        return
    me.vertices.add(len(v) // 3)
    me.attributes["position"].data.foreach_set("vector", v)
    me.loops.add(len(corner_verts))
    me.loops.foreach_set("vertex_index", np.ascontiguousarray(corner_verts, np.int32))
    me.polygons.add(len(sizes))
    me.polygons.foreach_set("loop_start", starts)
    me.update(calc_edges=True)


def read_polymesh(me: bpy.types.Mesh, matrix=None) -> PolyMesh:
    """The polygons and positions (float64; transformed by the 4x4 ``matrix`` if given) of ``me``."""
    pos = np.empty(3 * len(me.vertices), np.float32)
    if len(pos):   # an empty mesh has no position attribute
        me.attributes["position"].data.foreach_get("vector", pos)
    pos = pos.reshape(-1, 3).astype(np.float64)
    if matrix is not None:
        m = np.array(matrix, np.float64)
        pos = pos @ m[:3, :3].T + m[:3, 3]
    sizes = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_total", sizes)
    corners = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", corners)
    return PolyMesh(pos, sizes, corners)


# -- cache files -------------------------------------------------------------------------------------


def new_cache_path(name: str, registered: bool) -> str:
    """Absolute path for a new cache file (see the module docstring for the folder)."""
    return playback.new_cache_path(name, ".npy" if registered else ".scans", "scan_cache")


def write_cache(path: str, seq: ScanSequence) -> None:
    """Write the sequence's frames (no bpy: callable from a worker thread); a clear error when the
    cache cannot be written, and never a half-written one (written under ``.part``, then renamed)."""
    tmp = path + ".part"
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        if seq.registered:
            with open(tmp, "wb") as fh:
                np.save(fh, np.ascontiguousarray(seq.frames, np.float32))
        else:
            os.makedirs(tmp)
            for key, array in _unregistered_arrays(seq.meshes).items():
                np.save(os.path.join(tmp, key + ".npy"), array)
        os.replace(tmp, path)
    except OSError as exc:
        remove_cache(tmp)
        raise ArticulaInputError(f"cannot write the frame cache {path}: {exc.strerror or exc}") from None


def remove_cache(path: str) -> None:
    """Delete a cache (file or folder) that no object uses, e.g. after a failed import."""
    _loaded.forget(path)
    if os.path.isdir(path):
        shutil.rmtree(path, ignore_errors=True)
        return
    try:
        os.remove(path)
    except OSError:
        pass


def _unregistered_arrays(meshes) -> dict:
    def offsets(sizes):
        return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    return {"positions": np.concatenate([m.vertices for m in meshes]).astype(np.float32),
            "vertex_offsets": offsets([len(m.vertices) for m in meshes]),
            "face_sizes": np.concatenate([m.face_sizes for m in meshes]).astype(np.int32),
            "face_offsets": offsets([len(m.face_sizes) for m in meshes]),
            "corner_verts": np.concatenate([m.corner_verts for m in meshes]).astype(np.int32),
            "corner_offsets": offsets([len(m.corner_verts) for m in meshes])}


def _load(path: str):
    """np.memmap (.npy) or dict of memmaps (.scans folder)."""
    if os.path.isdir(path):
        return {k: np.load(os.path.join(path, k + ".npy"), mmap_mode="r")
                for k in ("positions", "vertex_offsets", "face_sizes", "face_offsets", "corner_verts",
                          "corner_offsets")}
    return np.load(path, mmap_mode="r")


_loaded = playback.FileCache(_load)


def cache_data(ob: bpy.types.Object):
    """The loaded cache of a scan-sequence object (memmap or dict), or raise naming the object."""
    path = playback.cache_abspath(ob)
    try:
        return _loaded.get(path)
    except (OSError, ValueError):
        what = "unreadable" if path and os.path.exists(path) else "missing"
        raise ArticulaInputError(f"{ob.name}: its frame cache {path or '(none)'} is {what}; "
                                 f"{playback.cache_advice(path, SOURCE)}") from None


def _frame_mesh(data, k: int) -> PolyMesh:
    v0, v1 = data["vertex_offsets"][k:k + 2]
    f0, f1 = data["face_offsets"][k:k + 2]
    c0, c1 = data["corner_offsets"][k:k + 2]
    return PolyMesh(data["positions"][v0:v1], data["face_sizes"][f0:f1], data["corner_verts"][c0:c1])


# -- the object ---------------------------------------------------------------------------------------


def create_object(context, name: str, seq: ScanSequence, cache_path: str, frame_start: int,
                  source: str, matrix=None) -> bpy.types.Object:
    """Create the scan-sequence object (its cache already written at ``cache_path``), link it to the
    active collection, make it active and make the scene's frame range cover the sequence
    (:func:`addon.scene.frames.include_frames`: widened, set outright only in an otherwise empty scene).  ``matrix``
    (4, 4): its object matrix, e.g. the files' axis conversion (the frames stay in file coordinates)."""
    me = bpy.data.meshes.new(name)
    topo = seq.topology
    set_geometry(me, topo.vertices, topo.face_sizes, topo.corner_verts)
    me[playback.SHOWN] = 0
    ob = bpy.data.objects.new(name, me)
    if matrix is not None:
        ob.matrix_world = Matrix(np.asarray(matrix, np.float64).tolist())
    context.collection.objects.link(ob)
    data = ob.articula
    data.kind = 'SCAN_SEQUENCE'
    data.registered = seq.registered
    data.source = source
    data.frame_start = frame_start
    data.frame_count = len(seq)
    data.cache_file = playback.stored_path(cache_path)
    scene = context.scene
    frames.include_frames(scene, frame_start, frame_start + len(seq) - 1, [ob])
    for other in context.view_layer.objects.selected:
        other.select_set(False)
    context.view_layer.objects.active = ob
    ob.select_set(True)
    playback.show(ob, scene.frame_current)
    return ob


def is_scan_sequence(ob) -> bool:
    return ob is not None and ob.type == 'MESH' and ob.articula.kind == 'SCAN_SEQUENCE'


def show_frame(ob: bpy.types.Object, k: int) -> None:
    """Put sequence frame ``k`` into ``ob``'s mesh (the player of :mod:`.playback`); raises when the
    cache is missing or does not match the mesh (its topology was edited, or it belongs to another)."""
    me = ob.data
    data = cache_data(ob)
    if ob.articula.registered:
        if data.ndim != 3 or data.shape[1] != len(me.vertices) or k >= len(data):
            raise ArticulaInputError(f"frame cache {ob.articula.cache_file} not matching the mesh (was it "
                                     f"edited?); import the {SOURCE} again")
        if len(me.vertices):
            me.attributes["position"].data.foreach_set("vector", np.ascontiguousarray(data[k]).reshape(-1))
            me.update()
    else:
        if k + 1 >= len(data["vertex_offsets"]):
            raise ArticulaInputError(f"frame cache {ob.articula.cache_file} has no frame {k + 1}; "
                                     f"import the {SOURCE} again")
        m = _frame_mesh(data, k)
        set_geometry(me, m.vertices, m.face_sizes, m.corner_verts)


def scan_frames(ob: bpy.types.Object):
    """All frames of a registered scan-sequence object for the solver, from its cache (source files
    are not read again): ``(frames (N, V, 3) float32, faces (F, 3) int32 triangles)``."""
    if not is_scan_sequence(ob):
        raise ArticulaInputError(f"{getattr(ob, 'name', ob)}: not a scan-sequence object")
    if not ob.articula.registered:
        raise ArticulaInputError(f"{ob.name}: the scans are not registered (topology changes between "
                                 f"frames); use scan_frame_meshes() or track them instead")
    data = cache_data(ob)
    if data.ndim != 3 or data.shape[1] != len(ob.data.vertices):
        raise ArticulaInputError(f"{ob.name}: mesh has {len(ob.data.vertices)} vertices but its frame cache "
                                 f"has {data.shape[1] if data.ndim == 3 else '?'}; was the mesh edited?")
    return np.array(data, np.float32), mesh_io.read_triangles(ob.data)


def scan_frame_meshes(ob: bpy.types.Object) -> list:
    """One :class:`PolyMesh` per frame (registered or not), from the cache."""
    if not is_scan_sequence(ob):
        raise ArticulaInputError(f"{getattr(ob, 'name', ob)}: not a scan-sequence object")
    data = cache_data(ob)
    if ob.articula.registered:
        topo = read_polymesh(ob.data)
        return [PolyMesh(np.array(f, np.float64), topo.face_sizes, topo.corner_verts) for f in data]
    return [PolyMesh(*(np.array(a) for a in (m.vertices, m.face_sizes, m.corner_verts)))
            for m in (_frame_mesh(data, k) for k in range(len(data["vertex_offsets"]) - 1))]


# -- playback ------------------------------------------------------------------------------------------


def register_extra():
    playback.add_player('SCAN_SEQUENCE', playback.Player("scan", show_frame, _loaded.forget, SOURCE))


def unregister_extra():
    playback.remove_player('SCAN_SEQUENCE')


classes = ()
