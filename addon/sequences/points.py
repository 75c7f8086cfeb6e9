"""Blender half of depth recordings and point-cloud sequences.

What an import creates (in a collection named after the recording folder):

* a **camera** object matching the depth camera's intrinsics (see :func:`set_camera_intrinsics`),
  placed at the sensor pose ``world_from_sensor`` (from the fitted floor: world Z up, camera above the
  origin), so the user can look through it and see the points over their pixels;
* a **point-cloud object**: a mesh with vertices only (Blender's PointCloud datablock cannot be
  resized from Python in 4.2, and a mesh works in every version), parented to the camera with the
  local rotation ``diag(1, -1, -1)``.  Its vertex positions are the *sensor-frame* points (x right,
  y down, z forward), so world = ``camera.matrix_world @ diag(1, -1, -1, 1) @ p``, which is exactly
  how a Blender camera (looking down -Z, +Y up) sees the sensor frame.  Without intrinsics (plain
  point-cloud files) the object gets ``world_from_sensor`` as its own transform.
  Attributes: ``color`` (FLOAT_COLOR, linear, when colours were imported) and ``sensor_normal``
  (FLOAT_VECTOR, sensor frame) on the POINT domain.
  A Geometry Nodes modifier ("Articula Points": Mesh to Points + material) turns the vertices into
  renderable points of ``point_radius`` for Cycles, EEVEE and Workbench.

Playback: every frame of the recording lives in ONE cache file (``solver.depth.recording``, path in
``ob.articula.cache_file``; ``//`` = relative to the .blend).  A persistent ``frame_change_pre``
handler (pre, so the new positions are part of the frame's own evaluation, also when rendering an
animation) rewrites the mesh of each point-cloud object from the cached arrays: the frame shown is
``scene.frame_current - ob.articula.frame_start`` clamped to the recording.  The cache is read once
per file and kept in memory (re-read when the file changes).  The mesh saved in the .blend holds the
frame shown when saving, so a file opened without the add-on still shows one frame.
"""
from __future__ import annotations

import os

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ...solver.errors import ArticulaInputError
from .. import compat
from ...solver.depth.recording import PointSequence

SENSOR_TO_BLENDER_CAMERA = np.diag([1.0, -1.0, -1.0, 1.0])  # its own inverse
NODE_GROUP = "Articula Points"
MATERIAL = "Articula Points"
SENSOR_WIDTH_MM = 36.0

_sequences: dict = {}   # abspath -> (mtime_ns, size, PointSequence)
_shown: dict = {}       # mesh pointer -> (abspath, frame index) last written


# ---------------------------------------------------------------------------------------- camera

def set_camera_intrinsics(cam_data, scene, width, height, fx, fy, cx, cy) -> None:
    """Make a Blender camera reproduce a pinhole depth camera exactly (checked with
    ``world_to_camera_view`` in the tests, to 1e-4 px).

    Pixel centres are at integer (u, v) (column right, row down), so normalised view coordinates
    are ``x = (u + 0.5) / W`` and ``y = 1 - (v + 0.5) / H``.
    * sensor fit HORIZONTAL, sensor width 36 mm, ``lens = fx * 36 / W`` (mm);
    * non-square pixels (fx != fy): pixel aspect ``ax / ay = fy / fx`` (the larger one is 1);
    * principal point: ``shift_x = ((W - 1) / 2 - cx) / W``, ``shift_y = (cy - (H - 1) / 2) ay / (W ax)``
      (shifts are fractions of the sensor width; a principal point below the centre shifts the view up);
    * render resolution W x H at 100 %.
    """
    cam_data.sensor_fit = 'HORIZONTAL'
    cam_data.sensor_width = SENSOR_WIDTH_MM
    cam_data.lens = fx * SENSOR_WIDTH_MM / width
    ax, ay = (fy / fx, 1.0) if fy >= fx else (1.0, fx / fy)
    cam_data.shift_x = ((width - 1) / 2 - cx) / width
    cam_data.shift_y = (cy - (height - 1) / 2) * ay / (width * ax)
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = int(width), int(height), 100
    r.pixel_aspect_x, r.pixel_aspect_y = ax, ay


# ----------------------------------------------------------------------------------- cache files

def cache_abspath(ob) -> str:
    return os.path.normpath(bpy.path.abspath(ob.articula.cache_file)) if ob.articula.cache_file else ""


def load_sequence(path: str) -> PointSequence:
    """The cached :class:`PointSequence` of ``path`` (read once, re-read when the file changed)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ArticulaInputError(f"{path}: point cache missing ({exc.strerror or exc})") from exc
    hit = _sequences.get(path)
    if hit and hit[0] == st.st_mtime_ns and hit[1] == st.st_size:
        return hit[2]
    seq = PointSequence.load(path)
    _sequences[path] = (st.st_mtime_ns, st.st_size, seq)
    return seq


def forget_cache(path: str | None = None) -> None:
    if path is None:
        _sequences.clear()
        _shown.clear()
    else:
        _sequences.pop(path, None)


# ------------------------------------------------------------------------------------ frame data

def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def write_frame(mesh, seq: PointSequence, k: int) -> None:
    """Replace the vertices (and point attributes) of ``mesh`` by frame ``k`` of ``seq``."""
    sl = seq.frame(k)
    pts = np.ascontiguousarray(seq.points[sl], dtype=np.float32)
    mesh.clear_geometry()
    mesh.vertices.add(len(pts))
    if len(pts):
        mesh.attributes["position"].data.foreach_set("vector", pts.ravel())
    if seq.normals is not None:
        attr = mesh.attributes.get("sensor_normal") or mesh.attributes.new("sensor_normal", 'FLOAT_VECTOR', 'POINT')
        if len(pts):
            attr.data.foreach_set("vector", np.ascontiguousarray(seq.normals[sl], np.float32).ravel())
    if seq.colors is not None:
        attr = mesh.attributes.get("color") or mesh.attributes.new("color", 'FLOAT_COLOR', 'POINT')
        rgba = getattr(seq, "_linear_rgba", None)
        if rgba is None:  # converted once per sequence: cached sRGB values -> linear RGBA
            rgba = np.ones((len(seq.colors), 4), np.float32)
            rgba[:, :3] = _srgb_to_linear(np.clip(seq.colors, 0, 1))
            seq._linear_rgba = rgba
        if len(pts):
            attr.data.foreach_set("color", np.ascontiguousarray(rgba[sl]).ravel())
        mesh.color_attributes.active_color = attr
    mesh.update()


def frame_index(ob, scene, count: int) -> int:
    return int(min(max(scene.frame_current - ob.articula.frame_start, 0), count - 1))


def sequence_objects(scene):
    return [ob for ob in scene.objects
            if ob.type == 'MESH' and ob.articula.kind == 'POINT_CLOUD_SEQUENCE' and ob.articula.cache_file
            and ob.data.library is None and ob.mode != 'EDIT']  # linked / edited meshes are left alone


def update_scene(scene, force: bool = False) -> None:
    """Show the current frame on every point-cloud object of ``scene`` (missing caches are skipped
    with one message each: the mesh keeps the last frame it showed)."""
    for ob in sequence_objects(scene):
        path = cache_abspath(ob)
        try:
            seq = load_sequence(path)
        except ArticulaInputError as exc:
            if _shown.get(ob.data.as_pointer(), (None,))[0] != ("missing", path):
                print(f"Articula: {ob.name}: {exc}")
                _shown[ob.data.as_pointer()] = (("missing", path), -1)
            continue
        if seq.frame_count == 0:
            continue
        k = frame_index(ob, scene, seq.frame_count)
        key = ob.data.as_pointer()
        if not force and _shown.get(key) == (path, k):
            continue
        write_frame(ob.data, seq, k)
        _shown[key] = (path, k)


@persistent
def _on_frame_change(scene, depsgraph=None):
    update_scene(scene)


@persistent
def _on_load(*_args):
    _shown.clear()
    for scene in bpy.data.scenes:
        update_scene(scene, force=True)


_HANDLERS = ((bpy.app.handlers.frame_change_pre, _on_frame_change),
             (bpy.app.handlers.load_post, _on_load),
             (bpy.app.handlers.undo_post, _on_load),   # undo/redo restore a mesh holding some frame:
             (bpy.app.handlers.redo_post, _on_load))   # show the current one again


def register_extra():
    for hlist, fn in _HANDLERS:
        # remove stale copies from an earlier load of this module (add-on reload)
        for old in [h for h in hlist if getattr(h, "__name__", "") == fn.__name__
                    and getattr(h, "__module__", "") == fn.__module__]:
            hlist.remove(old)
        hlist.append(fn)


def unregister_extra():
    for hlist, fn in _HANDLERS:
        for old in [h for h in hlist if getattr(h, "__name__", "") == fn.__name__
                    and getattr(h, "__module__", "") == fn.__module__]:
            hlist.remove(old)
    forget_cache()


# ----------------------------------------------------------------------------------- display

def points_node_group():
    """Geometry Nodes group: Mesh to Points (radius from the modifier input) + the points material."""
    ng = bpy.data.node_groups.get(NODE_GROUP)
    if ng is not None and ng.bl_idname == 'GeometryNodeTree':
        return ng
    ng = bpy.data.node_groups.new(NODE_GROUP, 'GeometryNodeTree')
    ng.interface.new_socket("Geometry", in_out='INPUT', socket_type='NodeSocketGeometry')
    radius = ng.interface.new_socket("Radius", in_out='INPUT', socket_type='NodeSocketFloat')
    radius.default_value, radius.min_value = 0.004, 0.0
    ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    nodes, links = ng.nodes, ng.links
    n_in = nodes.new('NodeGroupInput')
    n_out = nodes.new('NodeGroupOutput')
    to_points = nodes.new('GeometryNodeMeshToPoints')
    set_mat = nodes.new('GeometryNodeSetMaterial')
    set_mat.inputs["Material"].default_value = points_material()
    n_in.location, to_points.location, set_mat.location, n_out.location = (-400, 0), (-150, 0), (80, 0), (300, 0)
    links.new(n_in.outputs[0], to_points.inputs["Mesh"])
    links.new(n_in.outputs[1], to_points.inputs["Radius"])
    links.new(to_points.outputs[0], set_mat.inputs["Geometry"])
    links.new(set_mat.outputs[0], n_out.inputs[0])
    return ng


def points_material():
    """A material reading the ``color`` point attribute (grey when absent)."""
    mat = bpy.data.materials.get(MATERIAL)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(MATERIAL)
    if not compat.at_least(5, 0):  # 5.0+: materials always use nodes (use_nodes is deprecated)
        mat.use_nodes = True
    mat.diffuse_color = (0.8, 0.8, 0.8, 1.0)
    nt = mat.node_tree
    bsdf = next((n for n in nt.nodes if n.type == 'BSDF_PRINCIPLED'), None)
    if bsdf is None:
        bsdf = nt.nodes.new('ShaderNodeBsdfPrincipled')
        out = next(n for n in nt.nodes if n.type == 'OUTPUT_MATERIAL')
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    attr = nt.nodes.new('ShaderNodeAttribute')
    attr.attribute_type = 'GEOMETRY'
    attr.attribute_name = "color"
    attr.location = (bsdf.location[0] - 300, bsdf.location[1])
    nt.links.new(attr.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def add_points_modifier(ob, radius: float):
    """Add the points modifier.  The radius is set through the group's socket default, which a new
    modifier copies (no ID-property access, whose API differs between 4.x and 5.x); users change it
    in the modifier panel."""
    ng = points_node_group()
    sock = next(item for item in ng.interface.items_tree
                if getattr(item, "in_out", None) == 'INPUT' and item.name == "Radius")
    sock.default_value = float(radius)
    mod = ob.modifiers.new("Articula Points", 'NODES')
    mod.node_group = ng
    return mod


# ---------------------------------------------------------------------------------------- create

def create_sequence_objects(context, name: str, seq: PointSequence, cache_file: str, source: str,
                            frame_start: int = 1, point_radius: float = 0.004, set_scene: bool = True):
    """Create the collection, camera (when ``seq.intrinsics``) and point-cloud object; return
    ``(points_object, camera_object or None)``.  Call inside ``jobs.scene_guard()``."""
    scene = context.scene
    coll = bpy.data.collections.new(name)
    scene.collection.children.link(coll)
    world = np.asarray(seq.world_from_sensor, float)
    cam_ob = None
    if seq.intrinsics is not None:
        w, h, fx, fy, cx, cy = seq.intrinsics
        cam_data = bpy.data.cameras.new(f"{name} Camera")
        cam_data.clip_start, cam_data.clip_end = 0.05, 100.0
        cam_ob = bpy.data.objects.new(f"{name} Camera", cam_data)
        coll.objects.link(cam_ob)
        cam_ob.matrix_world = _matrix(world @ SENSOR_TO_BLENDER_CAMERA)
        set_camera_intrinsics(cam_data, scene, int(w), int(h), fx, fy, cx, cy)
        if set_scene and scene.camera is None:
            scene.camera = cam_ob
    me = bpy.data.meshes.new(f"{name} Points")
    ob = bpy.data.objects.new(f"{name} Points", me)
    coll.objects.link(ob)
    if cam_ob is not None:
        ob.parent = cam_ob
        ob.matrix_parent_inverse.identity()
        ob.matrix_basis = _matrix(SENSOR_TO_BLENDER_CAMERA)
    else:
        ob.matrix_world = _matrix(world)
    data = ob.articula
    data.kind = 'POINT_CLOUD_SEQUENCE'
    data.source = source
    data.frame_start = frame_start
    data.frame_count = seq.frame_count
    data.cache_file = cache_file
    add_points_modifier(ob, point_radius)
    if set_scene:
        scene.frame_start = frame_start
        scene.frame_end = frame_start + max(seq.frame_count, 1) - 1
    path = cache_abspath(ob)
    _sequences[path] = (os.stat(path).st_mtime_ns, os.stat(path).st_size, seq)
    k = frame_index(ob, scene, seq.frame_count)
    write_frame(me, seq, k)
    _shown[me.as_pointer()] = (path, k)
    for o in context.view_layer.objects:
        o.select_set(False)
    ob.select_set(True)
    context.view_layer.objects.active = ob
    return ob, cam_ob


def _matrix(m):
    from mathutils import Matrix
    return Matrix([list(map(float, row)) for row in np.asarray(m)])


def default_cache_path(name: str) -> str:
    """Where a new cache goes: beside the saved .blend (``//<name>.points.npz``, relative), else in the
    extension's user folder (absolute; survives restarts)."""
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or "points"
    if bpy.data.filepath:
        base = f"//{safe}.points.npz"
        k = 1
        while os.path.exists(bpy.path.abspath(base)):
            k += 1
            base = f"//{safe}.{k}.points.npz"
        return base
    from .. import package_name
    folder = bpy.utils.extension_path_user(package_name(), path="point_clouds", create=True)
    k = 1
    path = os.path.join(folder, f"{safe}.points.npz")
    while os.path.exists(path):
        k += 1
        path = os.path.join(folder, f"{safe}.{k}.points.npz")
    return path


# ----------------------------------------------------------------------------- images via Blender

def load_image_pixels(path: str, what: str) -> np.ndarray:
    """(H, W, 4) float32 pixels of an image file read by Blender (rows top to bottom, as stored in
    the file), values as stored (no colour management).  Main thread only."""
    if not os.path.isfile(path):
        raise ArticulaInputError(f"{path}: {what} file missing")
    try:
        img = bpy.data.images.load(path, check_existing=False)
    except RuntimeError as exc:
        raise ArticulaInputError(f"{path}: cannot read {what} ({exc})") from exc
    try:
        try:
            img.colorspace_settings.is_data = True
        except (AttributeError, TypeError):
            pass
        w, h = img.size
        if w == 0 or h == 0:
            raise ArticulaInputError(f"{path}: cannot read {what} (empty or unsupported image)")
        buf = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(buf)
        return buf.reshape(h, w, 4)[::-1]
    finally:
        bpy.data.images.remove(img)


def load_exr_depth(path: str) -> np.ndarray:
    """Depth from an OpenEXR (or other float) image: the first channel, in metres, (H, W) float32."""
    return np.ascontiguousarray(load_image_pixels(path, "EXR depth")[:, :, 0])


def load_color(path: str) -> np.ndarray:
    """An 8-bit colour frame (PNG/JPG) as (H, W, 3) uint8 (sRGB values as stored)."""
    px = load_image_pixels(path, "colour frame")
    return np.clip(px[:, :, :3] * 255 + 0.5, 0, 255).astype(np.uint8)
