"""``articula.import_depth``: a depth recording (16-bit PNG / EXR frames) or a point-cloud sequence
(PLY / XYZ / NPY frames) -> a point-cloud object that follows the frame, plus a matching camera.

Thin: ``prepare`` turns the options into a plan (``addon/depth/plan.py``: frames, intrinsics, colour
frames read by Blender), the worker runs it (``solver/depth/recording.py``) and ``finish`` builds the
scene (``addon/sequences/points.py``) and reports.  docs/import_depth.md describes the options.
Scripts: ``bpy.ops.articula.import_depth(directory=..., preset='kinect_v1', ...)`` (the names of
``solver.depth.camera.CAMERA_PRESETS``).
"""
import time

import bpy

from ..addon.depth import plan as depth_plan
from ..addon.jobs import JobOperator
from ..solver.depth import camera
from ..solver.depth import frames as dp

PRESET_ITEMS = (
    ('FOLDER', "From Folder", "Read intrinsics.json from the depth folder (required for depth images "
                              "unless an intrinsics file or a camera preset is given)"),
    *((p.name, p.label, p.description) for p in camera.CAMERA_PRESETS),
)
LAST_TIMINGS = {}  # seconds of the last successful import: decode, processing, solver, cache, blender


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
        description="Where to write the point cache (.npz); default beside the .blend in <name>_articula/, or "
                    "the cache folder when the file is unsaved (moved beside the .blend when it is saved)")
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
    def prepare(self, context):
        opts = dp.DepthOptions(
            depth_scale=self.depth_scale, depth_min=self.depth_min, depth_max=self.depth_max,
            remove_floor=self.remove_floor, floor_tolerance=self.floor_tolerance,
            subtract_background=self.subtract_background, background_frames=self.background_frames,
            background_tolerance=self.background_tolerance, depth_noise=self.depth_noise,
            voxel_size=self.voxel_size, estimate_normals=self.estimate_normals)
        plan = depth_plan.plan_import(
            self.directory, opts, scale_given=self.properties.is_property_set("depth_scale"),
            intrinsics=self.intrinsics, preset=self.preset, background=self.background,
            color_directory=self.color_directory, cache_file=self.cache_file, name=self.collection_name)
        return lambda progress: (plan, plan.run(progress))

    def finish(self, context, result):
        plan, seq = result
        t0 = time.perf_counter()
        ob, _ = plan.build(context, seq, self.frame_start, self.point_radius)
        LAST_TIMINGS.clear()
        LAST_TIMINGS.update(seq.timings, blender=time.perf_counter() - t0)
        counts = seq.offsets[1:] - seq.offsets[:-1]
        msg = (f"{ob.name}: {seq.frame_count} frames, {int(counts.min())}-{int(counts.max())} points per frame"
               + (f"; {'; '.join(seq.notes)}" if seq.notes else ""))
        self.report({'INFO'}, msg)


classes = (ARTICULA_OT_import_depth,)
