"""``articula.import_depth``: a depth recording (16-bit PNG / EXR frames) or a point-cloud sequence
(PLY / XYZ / NPY frames) -> a point-cloud object that follows the frame, plus a matching camera.

Thin: gathers the inputs (files, intrinsics, colour frames read by Blender) in ``prepare``, runs
``solver.depth.recording`` in ``work`` and builds the scene with ``addon.sequences.points`` in
``finish``.  Scripts: ``bpy.ops.articula.import_depth(directory=..., preset='KINECT_V1', ...)``.
"""
import os
import time

import bpy

from ..addon.sequences import points as pcs
from ..addon.jobs import JobOperator
from ..solver.depth import camera
from ..solver.depth import frames as dp
from ..solver.depth import recording as ps
from ..solver.errors import ArticulaInputError

PRESET_ITEMS = (
    ('FOLDER', "From Folder", "Read intrinsics.json from the depth folder (required for depth images "
                              "unless an intrinsics file or a camera preset is given)"),
    ('KINECT_V1', "Kinect v1", "Nominal Kinect v1 / PrimeSense: 640x480, fx = fy = 580 px"),
    ('KINECT_V2', "Kinect v2", "Nominal Kinect v2: 512x424, 70.6 x 60 degrees"),
    ('AZURE_KINECT', "Azure Kinect (NFOV)", "Nominal Azure Kinect DK narrow field of view: 640x576, 75 x 65 degrees"),
    ('REALSENSE_D435', "RealSense D435", "Nominal Intel RealSense D435: 848x480, 87 x 58 degrees"),
)
LAST_TIMINGS = {}  # seconds of the last successful import: decode, processing, solver, cache, blender

PRESET_NAMES = {'KINECT_V1': "kinect_v1", 'KINECT_V2': "kinect_v2", 'AZURE_KINECT': "azure_kinect_nfov",
                'REALSENSE_D435': "realsense_d435"}


def _depth_frame(path: str) -> ps.DepthFrame:
    """PNG frames are decoded in the worker thread; EXR frames need Blender, so they are read now."""
    if path.lower().endswith(".exr"):
        data = pcs.load_exr_depth(path)
        return ps.DepthFrame(path, lambda: data, metres=True)
    return ps.png_frames([path])[0]


class ARTICULA_OT_import_depth(JobOperator, bpy.types.Operator):
    """Import a depth recording or point-cloud sequence as a point-cloud object that follows the frame,
    with a camera matching the depth camera"""
    bl_idname = "articula.import_depth"
    bl_label = "Import Depth Recording"
    bl_options = {'REGISTER', 'UNDO'}
    job_label = "Import depth"

    directory: bpy.props.StringProperty(
        name="Folder", subtype='DIR_PATH', options={'SKIP_SAVE'},  # not remembered: the button always browses
        description="Folder of depth frames (16-bit PNG in depth units, or EXR in metres) or of point-cloud "
                    "frames (PLY, XYZ, NPY), in natural name order")
    filter_folder: bpy.props.BoolProperty(default=True, options={'HIDDEN', 'SKIP_SAVE'})
    intrinsics: bpy.props.StringProperty(
        name="Intrinsics", subtype='FILE_PATH',
        description="intrinsics.json of the depth camera (overrides the preset)")
    preset: bpy.props.EnumProperty(name="Camera", items=PRESET_ITEMS, default='FOLDER')
    depth_scale: bpy.props.FloatProperty(
        name="Depth Scale", default=0.001, min=1e-6, precision=5,
        description="Metres per PNG depth unit (0.001 for millimetres); when not given, an intrinsics "
                    "file's depth_unit_m is used")
    depth_min: bpy.props.FloatProperty(name="Min Depth", default=0.3, min=0.0, unit='LENGTH')
    depth_max: bpy.props.FloatProperty(name="Max Depth", default=5.0, min=0.0, unit='LENGTH')
    remove_floor: bpy.props.BoolProperty(
        name="Remove Floor", default=True,
        description="Fit the floor plane (RANSAC + least squares, within 60 degrees of level) and remove "
                    "points on or below it; also places the camera above the world origin, Z up")
    floor_tolerance: bpy.props.FloatProperty(name="Floor Tolerance", default=0.02, min=0.001, unit='LENGTH')
    subtract_background: bpy.props.BoolProperty(
        name="Subtract Background", default=False,
        description="Remove pixels within the tolerance of the background: the background frame if given, "
                    "else the per-pixel median of the first frames (the subject must move)")
    background: bpy.props.StringProperty(name="Background Frame", subtype='FILE_PATH',
                                         description="Depth frame of the empty scene (optional)")
    background_frames: bpy.props.IntProperty(name="Background Frames", default=10, min=1)
    background_tolerance: bpy.props.FloatProperty(
        name="Background Tolerance", default=0.05, min=0.001, unit='LENGTH',
        description="Pixels must be this much (plus the noise term) in front of the background to be kept")
    depth_noise: bpy.props.FloatProperty(
        name="Depth Noise", default=0.01, min=0.0, precision=4,
        description="Floor and background tolerances grow by this times depth squared along the ray (1/m): "
                    "sensor noise grows with the square of the distance; 0 = fixed tolerances")
    voxel_size: bpy.props.FloatProperty(
        name="Voxel Size", default=0.0, min=0.0, precision=4, unit='LENGTH',
        description="Average the points in cubes of this size (0 = keep every point)")
    estimate_normals: bpy.props.BoolProperty(name="Normals", default=True,
                                             description="Store per-point normals (attribute sensor_normal)")
    color_directory: bpy.props.StringProperty(
        name="Colour Folder", subtype='DIR_PATH',
        description="Optional colour frames (PNG/JPG) registered to the depth frames, one per frame")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1)
    point_radius: bpy.props.FloatProperty(name="Point Radius", default=0.004, min=0.0, precision=4,
                                          unit='LENGTH')
    cache_file: bpy.props.StringProperty(
        name="Cache File", subtype='FILE_PATH',
        description="Where to write the point cache (.npz); default beside the .blend, or the extension's "
                    "user folder when the file is unsaved")
    collection_name: bpy.props.StringProperty(name="Name", description="Collection name (default: the folder name)")
    run_modal: bpy.props.BoolProperty(default=False, options={'HIDDEN', 'SKIP_SAVE'})

    # -- UI ---------------------------------------------------------------------------------------
    def invoke(self, context, event):
        if not self.directory and not bpy.app.background:
            self.run_modal = True
            context.window_manager.fileselect_add(self)
            return {'RUNNING_MODAL'}
        return JobOperator.invoke(self, context, event)

    def execute(self, context):
        if self.run_modal and not bpy.app.background:
            # Confirmed in the file browser (which calls execute): start the same import again through
            # invoke, the modal path with progress bar and Esc, with the chosen options.
            props = {p.identifier: getattr(self, p.identifier) for p in self.properties.bl_rna.properties
                     if not p.is_readonly and p.identifier not in ("rna_type", "run_modal")
                     and self.properties.is_property_set(p.identifier)}  # unset stay unset (depth_scale)
            bpy.ops.articula.import_depth('INVOKE_DEFAULT', **props)
            return {'CANCELLED'}  # this call itself changed nothing (no extra undo step)
        return JobOperator.execute(self, context)

    def draw(self, context):
        """Options beside the file browser, grouped."""
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column(heading="Camera")
        col.prop(self, "preset")
        col.prop(self, "intrinsics")
        col.prop(self, "depth_scale")
        col = layout.column(heading="Depth Range")
        col.prop(self, "depth_min")
        col.prop(self, "depth_max")
        col.prop(self, "depth_noise")
        col = layout.column(heading="Floor")
        col.prop(self, "remove_floor", text="Remove")
        sub = col.column()
        sub.active = self.remove_floor
        sub.prop(self, "floor_tolerance", text="Tolerance")
        col = layout.column(heading="Background")
        col.prop(self, "subtract_background", text="Subtract")
        sub = col.column()
        sub.active = self.subtract_background
        sub.prop(self, "background", text="Frame")
        sub.prop(self, "background_frames", text="Median of")
        sub.prop(self, "background_tolerance", text="Tolerance")
        col = layout.column(heading="Points")
        col.prop(self, "voxel_size")
        col.prop(self, "estimate_normals")
        col.prop(self, "point_radius")
        col.prop(self, "color_directory")
        col = layout.column()
        col.prop(self, "frame_start")
        col.prop(self, "collection_name")
        col.prop(self, "cache_file")

    # -- job ------------------------------------------------------------------------------------
    def _intrinsics(self, directory, needed):
        if self.intrinsics:
            return camera.load_intrinsics(bpy.path.abspath(self.intrinsics))
        if self.preset != 'FOLDER':
            return camera.preset(PRESET_NAMES[self.preset])
        path = os.path.join(directory, "intrinsics.json")
        if os.path.isfile(path):
            return camera.load_intrinsics(path)
        if needed:
            raise ArticulaInputError(f"{directory}: no intrinsics.json; give an intrinsics file or choose a "
                                     "camera preset (e.g. Kinect v1)")
        return None

    def prepare(self, context):
        directory = os.path.normpath(bpy.path.abspath(self.directory)) if self.directory else ""
        if not directory or not os.path.isdir(directory):
            raise ArticulaInputError(f"{self.directory or '(no folder given)'}: not a folder")
        try:
            paths = ps.list_frames(directory, ps.DEPTH_EXTENSIONS)
            clouds = False
        except ArticulaInputError:
            try:
                paths = ps.list_frames(directory, ps.CLOUD_EXTENSIONS)
            except ArticulaInputError:
                raise ArticulaInputError(
                    f"{directory}: no frames found (expected depth images {', '.join(ps.DEPTH_EXTENSIONS)} "
                    f"or point clouds {', '.join(ps.CLOUD_EXTENSIONS)})") from None
            clouds = True
        intr = self._intrinsics(directory, needed=not clouds)
        scale = self.depth_scale
        if intr is not None and not self.properties.is_property_set("depth_scale"):
            scale = intr.depth_unit_m  # 0.001 for the presets
        opts = dp.DepthOptions(
            depth_scale=scale, depth_min=self.depth_min, depth_max=self.depth_max,
            remove_floor=self.remove_floor, floor_tolerance=self.floor_tolerance,
            subtract_background=self.subtract_background, background_frames=self.background_frames,
            background_tolerance=self.background_tolerance, depth_noise=self.depth_noise,
            voxel_size=self.voxel_size,
            estimate_normals=self.estimate_normals)
        opts.validate()
        name = self.collection_name or os.path.basename(directory.rstrip(os.sep)) or "Depth"
        frames = None if clouds else [_depth_frame(p) for p in paths]
        background = None
        if self.background and not clouds:
            background = _depth_frame(os.path.normpath(bpy.path.abspath(self.background)))
        colors = None
        if self.color_directory:
            if clouds:
                raise ArticulaInputError("colour frames go with depth images; point-cloud files carry their "
                                         "own colours (NPY/XYZ with 6 columns)")
            cdir = os.path.normpath(bpy.path.abspath(self.color_directory))
            cpaths = ps.list_frames(cdir, ps.COLOR_EXTENSIONS)
            if len(cpaths) != len(paths):
                raise ArticulaInputError(f"{cdir}: {len(cpaths)} colour frames for {len(paths)} depth frames; "
                                         "the counts must match")
            images = [pcs.load_color(p) for p in cpaths]
            colors = [(lambda im=im: im) for im in images]
        cache = self.cache_file or pcs.default_cache_path(name)
        cache_abs = os.path.normpath(bpy.path.abspath(cache))

        def work(progress):
            t0 = time.perf_counter()
            if clouds:
                seq = ps.import_clouds(paths, opts, progress, intr)
            else:
                seq = ps.import_depth(frames, intr, opts, progress, background, colors)
            t1 = time.perf_counter()
            seq.save(cache_abs)
            seq.timings.update(solver=t1 - t0, cache=time.perf_counter() - t1)
            return seq, cache, cache_abs, name, directory

        return work

    def finish(self, context, result):
        seq, cache, cache_abs, name, directory = result
        t0 = time.perf_counter()
        scene, render = context.scene, context.scene.render
        settings = (scene.camera, scene.frame_start, scene.frame_end, render.resolution_x, render.resolution_y,
                    render.resolution_percentage, render.pixel_aspect_x, render.pixel_aspect_y)
        try:
            ob, cam = pcs.create_sequence_objects(context, name, seq, cache, directory, self.frame_start,
                                                  self.point_radius)
            LAST_TIMINGS.clear()
            LAST_TIMINGS.update(seq.timings, blender=time.perf_counter() - t0)
        except BaseException:
            # scene_guard removes the new datablocks; put the scene settings back as well
            if scene.camera is not settings[0] and (settings[0] is None or settings[0].name in bpy.data.objects):
                scene.camera = settings[0]
            (scene.frame_start, scene.frame_end, render.resolution_x, render.resolution_y,
             render.resolution_percentage, render.pixel_aspect_x, render.pixel_aspect_y) = settings[1:]
            pcs.forget_cache(cache_abs)
            if os.path.exists(cache_abs):
                os.remove(cache_abs)
            raise
        counts = seq.offsets[1:] - seq.offsets[:-1]
        msg = (f"{ob.name}: {seq.frame_count} frames, {int(counts.min())}-{int(counts.max())} points per frame"
               + (f"; {'; '.join(seq.notes)}" if seq.notes else ""))
        self.report({'INFO'}, msg)


classes = (ARTICULA_OT_import_depth,)
