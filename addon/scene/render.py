"""Headless pictures of a scene (Workbench; works without a GPU through Mesa llvmpipe).

Used by the demo and by documentation pictures.  Bones and overlays never appear in renders
(``render.opengl`` is unavailable in background mode), so only meshes and points are shown.

Colours: every exhibit gets one colour of :data:`PALETTE` (object colour, Workbench ``OBJECT``
colouring).  Exhibits named in ``render_overview(..., attribute_colors=...)`` show their meshes'
active colour attribute instead (e.g. the learned rig's error heat map): the render then uses Workbench
``VERTEX`` ("Attribute") colouring, where objects without a colour attribute fall back to their
material's viewport colour, so every other object gets an overview material of its exhibit's colour
in an object-linked slot (the data's materials stay; an empty slot is added to data without any).  Meshes of other exhibits that
have an active colour attribute of their own show it too in that case.
"""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix, Vector

from .. import console

PALETTE = ((0.80, 0.62, 0.50, 1.0), (0.55, 0.70, 0.85, 1.0), (0.60, 0.80, 0.55, 1.0),
           (0.85, 0.75, 0.45, 1.0), (0.75, 0.55, 0.80, 1.0))
LABEL_COLOR = (0.1, 0.1, 0.1, 1.0)
GROUND_COLOR = (0.92, 0.92, 0.92, 1.0)


def world_bounds(objects) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (lo, hi) of the visible geometry of ``objects`` (world metres): the
    evaluated bounding box; for vertex-only meshes (point clouds drawn by a Geometry Nodes modifier,
    whose evaluated box is empty) the 1st-99th percentile box of the points, so stray points
    do not blow up the framing."""
    dg = bpy.context.evaluated_depsgraph_get()
    points = []
    for ob in objects:
        if ob.type not in {'MESH', 'POINTCLOUD', 'CURVE', 'FONT'} or not ob.visible_get():
            continue
        if ob.type == 'MESH' and len(ob.data.vertices) and not len(ob.data.polygons):
            co = np.empty(3 * len(ob.data.vertices), np.float32)
            ob.data.vertices.foreach_get("co", co)
            mw = np.array(ob.matrix_world)
            co = co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
            points.append(np.percentile(co, [1, 99], axis=0))
            continue
        ev = ob.evaluated_get(dg)
        points.append(np.array([ev.matrix_world @ Vector(c) for c in ev.bound_box]))
    points = [p for p in points if np.isfinite(p).all()]
    if not points:
        return np.zeros(3), np.ones(3)
    allp = np.concatenate(points)
    return allp.min(0), allp.max(0)


def add_label(text: str, location, size: float = 0.12, collection=None):
    """A text object lying on the floor in front of an exhibit, readable from the front camera."""
    curve = bpy.data.curves.new(f"Label {text}", 'FONT')
    curve.body = text
    curve.size = size
    curve.align_x = 'CENTER'
    ob = bpy.data.objects.new(f"Label {text}", curve)
    ob.location = location
    ob.rotation_euler = (np.pi / 2, 0.0, 0.0)
    ob.color = LABEL_COLOR
    (collection or bpy.context.scene.collection).objects.link(ob)
    return ob


def fit_labels(labels, centres_x, fill: float = 0.92) -> None:
    """Shrink the labels (all by one factor) so that none is wider than ``fill`` times the distance
    between neighbouring exhibit centres ``centres_x`` (one per label): long titles then do not run
    into each other."""
    if len(labels) < 2:
        return
    bpy.context.view_layer.update()
    pitch = float(np.diff(np.sort(np.asarray(centres_x, float))).min())
    widest = max(ob.dimensions.x for ob in labels)
    if pitch > 0 and widest > fill * pitch:
        factor = fill * pitch / widest
        for ob in labels:
            ob.data.size *= factor


def _look_at(cam_ob, eye, target) -> None:
    direction = Vector(target) - Vector(eye)
    cam_ob.matrix_world = Matrix.Translation(eye) @ direction.to_track_quat('-Z', 'Y').to_matrix().to_4x4()


def frame_camera(scene, lo, hi, name: str = "Overview Camera", azimuth_deg: float = -10.0,
                 elevation_deg: float = 12.0, lens_mm: float = 50.0):
    """Add (or reuse) a camera looking at the box [lo, hi] from the front (-Y), framing it fully."""
    cam_ob = bpy.data.objects.get(name)
    if cam_ob is None:
        cam_ob = bpy.data.objects.new(name, bpy.data.cameras.new(name))
        scene.collection.objects.link(cam_ob)
    cam_ob.data.lens = lens_mm
    cam_ob.data.sensor_fit = 'HORIZONTAL'
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = (lo + hi) / 2
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    back = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])  # centre -> eye
    forward = -back
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_x = cam_ob.data.sensor_width / (2 * lens_mm)
    tan_y = tan_x * scene.render.resolution_y / scene.render.resolution_x
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    rel = corners - centre
    # distance D such that every corner projects inside the frame (with a 5% margin)
    need = np.maximum(np.abs(rel @ right) / (0.95 * tan_x), np.abs(rel @ up) / (0.95 * tan_y)) - rel @ forward
    distance = float(need.max())
    eye = centre + distance * back
    _look_at(cam_ob, eye, centre)
    cam_ob.data.clip_end = max(100.0, 4 * distance)
    scene.camera = cam_ob
    return cam_ob


def setup_workbench(scene, width: int = 1280, height: int = 720, color_type: str = 'OBJECT') -> None:
    scene.render.engine = 'BLENDER_WORKBENCH'
    shading = scene.display.shading
    shading.light = 'STUDIO'
    shading.color_type = color_type
    shading.show_cavity = True
    shading.show_shadows = True
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = 'PNG'


def add_ground(scene, lo, hi, margin: float = 0.6):
    """A plain floor under the box [lo, hi] so Workbench shadows ground the exhibits."""
    size = float(max(hi[0] - lo[0], hi[1] - lo[1])) + 2 * margin
    me = bpy.data.meshes.new("Overview Ground")
    h = size / 2
    me.from_pydata([(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [], [(0, 1, 2, 3)])
    ob = bpy.data.objects.new("Overview Ground", me)
    ob.location = ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2])
    ob.color = GROUND_COLOR
    scene.collection.objects.link(ob)
    return ob


def overview_material(color, name: str = "Overview"):
    """A material whose viewport (Workbench) colour is ``color``, reused by name."""
    name = f"{name} {'/'.join(f'{c:.2f}' for c in color[:3])}"
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    mat.diffuse_color = color
    mat.metallic = 0.0
    mat.roughness = 0.5          # Workbench's roughness for object colours
    return mat


def paint(ob, color) -> None:
    """Show ``color`` on ``ob`` both as object colour and as material colour (object-linked material
    slots override the data's materials, which stay as they are; evaluated geometry such as a point
    cloud's Geometry Nodes output is covered too)."""
    ob.color = color
    data = getattr(ob, "data", None)
    if data is None or not hasattr(data, "materials") or not ob.visible_get():
        return
    if not len(ob.material_slots):
        data.materials.append(None)
    mat = overview_material(color)
    for slot in ob.material_slots:
        slot.link = 'OBJECT'
        slot.material = mat


def render_overview(scene, filepath: str, exhibits: dict, attribute_colors=(),
                    width: int = 1280, height: int = 720) -> None:
    """Render groups of objects (``{title: [objects]}``), one colour per group, each titled by a
    label on the floor in front of it, from a framing front camera to ``filepath`` (PNG,
    ``width`` x ``height``).  The groups whose titles are in ``attribute_colors`` show their meshes'
    active colour attribute (e.g. a heat map) instead of a palette colour."""
    shown = set(attribute_colors)
    unknown = shown - set(exhibits)
    if unknown:
        raise ValueError(f"attribute_colors: no exhibit titled {sorted(unknown)}")
    setup_workbench(scene, width, height, 'VERTEX' if shown else 'OBJECT')
    colour = paint if shown else (lambda ob, c: setattr(ob, "color", c))
    everything = [ob for group in exhibits.values() for ob in group]
    lo, hi = world_bounds(everything)
    labels, centres = [], []
    for i, (title, group) in enumerate(exhibits.items()):
        if title not in shown:
            for ob in group:
                colour(ob, PALETTE[i % len(PALETTE)])
        glo, ghi = world_bounds(group)
        centres.append((glo[0] + ghi[0]) / 2)
        labels.append(add_label(title, (centres[-1], lo[1] - 0.2, lo[2] + 0.001)))
    fit_labels(labels, centres)
    ground = add_ground(scene, lo, hi)
    for ob in labels + [ground]:
        colour(ob, ob.color[:])
    lo = lo - np.array([0.0, 0.3, 0.0])  # keep the labels in frame
    frame_camera(scene, lo, hi)
    scene.render.filepath = filepath
    with console.without_lines(console.EGL):    # the render succeeds through Mesa llvmpipe all the same
        bpy.ops.render.render(write_still=True)
