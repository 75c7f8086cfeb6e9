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

Playback (:mod:`.playback`: handlers, frame index, cache paths): every frame of the recording lives in
ONE cache file (``solver/formats/point_files.py``, path in ``ob.articula.cache_file``); a frame change
rewrites the mesh from the cached arrays.  The cache is read once per file and kept in memory (re-read
when the file changes).  The mesh saved in the .blend holds the frame shown when saving, so a file
opened without the add-on still shows one frame.  docs/import_depth.md describes the whole import.
"""
from __future__ import annotations

import bpy
import numpy as np

from ...solver.depth import camera
from ...solver.errors import ArticulaInputError
from ...solver.formats.point_files import PointSequence
from .. import compat
from ..scene import frames
from . import playback

SENSOR_TO_BLENDER_CAMERA = camera.blender_from_cv(np.eye(4))  # diag(1, -1, -1, 1): points in the camera
NODE_GROUP = "Articula Points"
MATERIAL = "Articula Points"
SENSOR_WIDTH_MM = 36.0


# ---------------------------------------------------------------------------------------- camera

def set_camera_intrinsics(cam_data, scene, intr: camera.Intrinsics) -> None:
    """Make a Blender camera (and the scene's render size) reproduce the pinhole depth camera ``intr``
    exactly (``camera.blender_camera_settings``: lens, sensor, shift, resolution, pixel aspect)."""
    settings = camera.blender_camera_settings(intr, SENSOR_WIDTH_MM)
    for key in ("sensor_fit", "sensor_width", "lens", "shift_x", "shift_y"):
        setattr(cam_data, key, settings[key])
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = settings["resolution_x"], settings["resolution_y"], 100
    r.pixel_aspect_x, r.pixel_aspect_y = settings["pixel_aspect_x"], settings["pixel_aspect_y"]


# ----------------------------------------------------------------------------------- cache files

_sequences = playback.FileCache(PointSequence.load)


SOURCE = "depth recording"   # what is imported again to rebuild a cache (messages)


def load_sequence(path: str, name: str = "") -> PointSequence:
    """The cached :class:`PointSequence` of ``path`` (read once, re-read when the file changed); a
    missing or unreadable cache raises naming the object ``name`` and what to do
    (:func:`playback.cache_advice`)."""
    who = f"{name}: " if name else ""
    try:
        return _sequences.get(path)
    except OSError:
        raise ArticulaInputError(f"{who}its point cache {path or '(none)'} is missing; "
                                 f"{playback.cache_advice(path, SOURCE)}") from None
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{who}{exc}; {playback.cache_advice(path, SOURCE)}") from None


def forget_cache(path: str | None = None) -> None:
    """Drop the loaded cache of ``path`` (all when None); the next frame change reads the file again."""
    _sequences.forget(path)


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


def show_frame(ob, k: int) -> None:
    """Put frame ``k`` of the object's cache into its mesh (the player of :mod:`.playback`)."""
    write_frame(ob.data, load_sequence(playback.cache_abspath(ob), ob.name), k)


def register_extra():
    playback.add_player('POINT_CLOUD_SEQUENCE', playback.Player("point-cloud", show_frame, forget_cache, SOURCE))


def unregister_extra():
    playback.remove_player('POINT_CLOUD_SEQUENCE')


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
    ``(points_object, camera_object or None)``.  With ``set_scene`` the scene's frame range is made to
    cover the sequence (:func:`addon.scene.frames.include_frames`) and its camera set when it has none.  Call
    inside ``jobs.scene_guard()``."""
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
        cam_ob.matrix_world = _matrix(camera.blender_from_cv(world))
        set_camera_intrinsics(cam_data, scene, camera.Intrinsics(int(w), int(h), fx, fy, cx, cy))
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
        frames.include_frames(scene, frame_start, frame_start + max(seq.frame_count, 1) - 1,
                                [o for o in (ob, cam_ob) if o is not None])
    _sequences.put(playback.cache_abspath(ob), seq)
    if seq.frame_count:
        playback.show(ob, scene.frame_current, force=True)
    for o in context.view_layer.objects:
        o.select_set(False)
    ob.select_set(True)
    context.view_layer.objects.active = ob
    return ob, cam_ob


def _matrix(m):
    from mathutils import Matrix
    return Matrix([list(map(float, row)) for row in np.asarray(m)])


def default_cache_path(name: str) -> str:
    """Absolute path for a new cache ``<name>-<id>.points.npz``: in the saved .blend's cache folder
    (``<blend name>_articula/``, stored ``//``-relative), else in the cache folder under
    ``point_clouds/``; it travels with the .blend when that is saved (:mod:`.playback`)."""
    return playback.new_cache_path(name, ".points.npz", "point_clouds")
