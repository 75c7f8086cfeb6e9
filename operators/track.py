"""``articula.track``: track a sequence of unregistered captures with a person's model and bake the motion
on the rig, which then plays over the captures, with per-frame residual curves (and, for scans, error
colours on the captures).

Input: the model of the Articula rig named ``rig`` (empty: the active or a selected rig), or of the
bundle file ``bundle``; the captures of the scan-sequence or point-cloud object named ``captures``
(empty: the one selected).  ``method`` picks the tracker: a depth recording (a point cloud imported with
its camera) goes to the depth-camera tracker (:mod:`addon.track_depth`; no rig or bundle: the built-in
template body, adapted to the person; the recording's camera becomes the scene camera), everything else
to the capture tracker (:mod:`addon.track`).  The settings' defaults come from
:class:`solver.track.options.TrackOptions` and :class:`solver.track_depth.options.DepthTrackOptions`.
"""
import os
from dataclasses import replace

import bpy

from ..addon import preferences
from ..addon.jobs import JobOperator
from ..addon.rig import reader
from ..addon.track import inputs, result, solve
from ..addon.track.report import summary_text
from ..addon.track_depth import inputs as depth_inputs
from ..addon.track_depth import result as depth_result
from ..addon.track_depth import solve as depth_solve
from ..addon.track_depth.report import summary_text as depth_summary
from ..addon.tracking.result import check_output_path
from ..solver.errors import ArticulaInputError
from ..solver.track.options import TrackOptions
from ..solver.track_depth.options import PERSON_CHOICES, TRACKERS, DepthTrackOptions

_DEFAULT = TrackOptions()
_DEPTH_DEFAULT = DepthTrackOptions()
TRACKER_ITEMS = tuple((t.upper(), t.upper(), {"icp": "Iterative closest points with silhouette edges (ch. 5)",
                                               "gmm": "Gaussian mixture of the body's surface (ch. 6)"}.get(t, t))
                      for t in TRACKERS)
PERSON_ITEMS = tuple((p.upper(), p.title(), {
    "centre": "The person nearest the middle of the image", "nearest": "The person nearest the camera",
    "largest": "The person filling most of the image", "left": "The leftmost person in the image",
    "right": "The rightmost person in the image"}[p]) for p in PERSON_CHOICES)
ADAPT_ITEMS = (('AUTO', "Auto", "Adapt the rest mesh and joints when the model is not the person's (its surface "
                                 "lies off the captures beyond their noise) and the range is long enough"),
               ('ON', "On", "Always adapt the model to the recording"),
               ('OFF', "Off", "Keep the model as it is"))
PRIOR_ITEMS = (('AUTO', "Auto", "The model's own training poses when it has some, else the generic human prior"),
               ('MODEL', "Model's Poses", "Learn the pose prior from the poses the model was trained on"),
               ('GENERIC', "Generic Human", "The generic human pose prior shipped with Articula"),
               ('NONE', "None", "No pose prior"))


class ARTICULA_OT_track(JobOperator, bpy.types.Operator):
    """Track unregistered captures (a scan-sequence or point-cloud object) with a person's rig, or a depth
    recording with a rig or the built-in template body: one pose per frame baked as an action, residual
    curves, error colours on scans"""
    bl_idname = "articula.track"
    bl_label = "Track Captures"
    bl_options = {'REGISTER', 'UNDO'}
    job_label = "Track"

    rig: bpy.props.StringProperty(
        name="Rig", options={'SKIP_SAVE'},
        description="Articula rig to track with (empty: the active or a selected rig)")
    bundle: bpy.props.StringProperty(
        name="Bundle", subtype='FILE_PATH', options={'SKIP_SAVE'},
        description="Model bundle (.npz) to track with instead of a rig in the scene; a rig is built from it")
    captures: bpy.props.StringProperty(
        name="Captures", options={'SKIP_SAVE'},
        description="Scan-sequence or point-cloud object to track (empty: the selected one)")
    method: bpy.props.EnumProperty(name="Tracker", items=depth_inputs.METHOD_ITEMS, default='AUTO',
                                   description="Which tracker follows the person")
    depth_tracker: bpy.props.EnumProperty(name="Depth Tracker", items=TRACKER_ITEMS,
                                          default=_DEPTH_DEFAULT.tracker.upper(),
                                          description="How the depth-camera tracker fits each frame")
    person: bpy.props.EnumProperty(name="Person", items=PERSON_ITEMS, default=_DEPTH_DEFAULT.person.upper(),
                                   description="With several people in view, whom the depth-camera tracker "
                                               "starts on (it then follows that person)")
    adapt: bpy.props.EnumProperty(name="Adapt Model", items=ADAPT_ITEMS, default=_DEFAULT.adapt.upper(),
                                  description="Refine the model's rest mesh and joints from the recording")
    prior: bpy.props.EnumProperty(name="Pose Prior", items=PRIOR_ITEMS, default=_DEFAULT.prior.upper(),
                                  description="Which pose prior keeps the joints in plausible poses")
    temporal: bpy.props.BoolProperty(
        name="Temporal Smoothing", default=_DEFAULT.temporal,
        description="Refine the poses in overlapping windows of frames with a prior on their acceleration")
    fit_scale: bpy.props.BoolProperty(name="Fit Scale", default=_DEFAULT.fit_scale,
                                      description="Also fit one uniform scale of the model")
    max_points: bpy.props.IntProperty(
        name="Max Points", default=_DEFAULT.max_points, min=0, soft_max=200_000,
        description="Thin every capture to about this many points before fitting (0: keep all)")
    start_from_rig: bpy.props.BoolProperty(
        name="Start From Rig's Pose", default=False, options={'SKIP_SAVE'},
        description="Start the first tracked frame from the pose the rig holds now (pose it roughly over that "
                    "capture) instead of searching for it; for rigs whose first frame is not found on its own")
    use_frame_range: bpy.props.BoolProperty(
        name="Frame Range", default=False, options={'SKIP_SAVE'},
        description="Track only the scene frames First..Last of the captures (else every frame)")
    frame_first: bpy.props.IntProperty(name="First", default=1, options={'SKIP_SAVE'})
    frame_last: bpy.props.IntProperty(name="Last", default=1, options={'SKIP_SAVE'})
    output_bundle: bpy.props.StringProperty(
        name="Save Bundle", subtype='FILE_PATH', options={'SKIP_SAVE'},
        description="Also write the tracked model and poses to this bundle (.npz); empty: do not write")
    name: bpy.props.StringProperty(name="Name", options={'SKIP_SAVE'},
                                   description="Name of a rig built for the result (empty: after the model)")
    confirmed: bpy.props.BoolProperty(default=False, options={'HIDDEN', 'SKIP_SAVE'})

    def invoke(self, context, event):
        if not self.confirmed and not bpy.app.background:
            self._dialog = True
            return context.window_manager.invoke_props_dialog(self, width=360)
        return JobOperator.invoke(self, context, event)

    def execute(self, context):
        if getattr(self, "_dialog", False) and not bpy.app.background:
            # Confirmed in the options dialog: run as a modal job (progress + Esc) on what is selected.
            self._dialog = False
            props = {p.identifier: getattr(self.properties, p.identifier)
                     for p in self.properties.bl_rna.properties if p.identifier != "rna_type"}
            props["confirmed"] = True
            bpy.ops.articula.track('INVOKE_DEFAULT', **props)
            return {'CANCELLED'}   # the job pushes its own undo step
        return JobOperator.execute(self, context)

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "bundle")
        col.prop(self, "method")
        sub = col.column()
        sub.enabled = self.method != 'CAPTURES'
        sub.prop(self, "depth_tracker")
        sub.prop(self, "person")
        box = col.box().column()
        box.enabled = self.method != 'DEPTH'
        box.label(text="Scans and point clouds:")
        for prop in ("adapt", "prior", "temporal", "fit_scale", "max_points"):
            box.prop(self, prop)
        sub = box.row()
        sub.enabled = not self.bundle.strip()
        sub.prop(self, "start_from_rig")
        col.prop(self, "use_frame_range")
        row = col.row(align=True)
        row.enabled = self.use_frame_range
        row.prop(self, "frame_first")
        row.prop(self, "frame_last")
        col.prop(self, "output_bundle")
        col.prop(self, "name")

    # -- job parts -----------------------------------------------------------------------------------
    def prepare(self, context):
        ob = inputs.find_captures(context, self.captures)
        out = bpy.path.abspath(self.output_bundle) if self.output_bundle else ""
        check_output_path(out)
        self._output = out
        if depth_inputs.uses_depth_tracker(ob, self.method):
            return self._prepare_depth(context, ob)
        options = TrackOptions(adapt=self.adapt.lower(), prior=self.prior.lower(), temporal=self.temporal,
                               fit_scale=self.fit_scale, max_points=self.max_points,
                               workers=preferences.threads(context)).validate()
        if self.bundle.strip():
            if self.start_from_rig:
                raise ArticulaInputError("Start From Rig's Pose needs a rig in the scene, not a bundle file")
            model_input = inputs.model_from_bundle(bpy.path.abspath(self.bundle))
        else:
            arm = inputs.find_rig(context, self.rig)
            model_input = inputs.model_from_rig(arm)
            if self.start_from_rig:
                model_input.start_pose = reader.read_current_pose(arm)    # object space: the solve frame
                model_input.start_label = "the rig's pose"
        model_input.matrix = inputs.solve_matrix(model_input, ob)
        captures = inputs.captures_from_object(ob, model_input.matrix)
        if self.use_frame_range:
            span = depth_inputs.frame_slice(self.frame_first, self.frame_last, len(captures.names),
                                            captures.frame_start)
            options = replace(options, frames=(span.start, span.stop)).validate()

        def work(progress):
            progress(0.0, "reading captures")
            return solve.track(model_input, captures, options, progress)
        return work

    def _prepare_depth(self, context, ob):
        """The depth-camera tracker on depth object ``ob``: the bundle, else the rig, else the template."""
        if self.start_from_rig:
            raise ArticulaInputError("Start From Rig's Pose is for scans and point clouds; the depth tracker "
                                     "finds the first frame's pose itself")
        options = DepthTrackOptions(tracker=self.depth_tracker.lower(), person=self.person.lower()).validate()
        bundle = bpy.path.abspath(self.bundle) if self.bundle.strip() else ""
        model_input = depth_inputs.find_model(context, self.rig, bundle)
        span = None
        if self.use_frame_range:
            span = depth_inputs.frame_slice(self.frame_first, self.frame_last, ob.articula.frame_count,
                                            ob.articula.frame_start)
        captures = depth_inputs.recording_from_object(ob, model_input.matrix, span)
        return lambda progress: depth_solve.track(model_input, captures, options, progress)

    def finish(self, context, outcome):
        if isinstance(outcome, depth_solve.DepthOutcome):
            return self._finish_depth(context, outcome)
        arm, action, warnings = result.build(context, outcome, self.name)
        if self._output:
            result.save(self._output, outcome)
        for text in warnings:
            self.report({'WARNING'}, text)
        for note in getattr(outcome.result, "notes", ()):
            self.report({'WARNING'}, f"{outcome.model_input.label}: {note}")
        saved = f"; saved {os.path.basename(self._output)}" if self._output else ""
        self.report({'INFO'}, f"Tracked {outcome.captures.label} with {arm.name!r} (action {action.name!r}): "
                              f"{summary_text(outcome)}{saved}")

    def _finish_depth(self, context, outcome):
        arm, action, warnings = depth_result.build(context, outcome, self.name)
        if self._output:
            depth_result.save(self._output, outcome)
        seen = depth_result.look_through(context, outcome.captures.camera_name)
        for text in warnings:
            self.report({'WARNING'}, text)
        for note in outcome.result.notes:
            self.report({'INFO'}, f"{outcome.captures.label}: {note}")
        saved = f"; saved {os.path.basename(self._output)}" if self._output else ""
        camera = f"; seen through {outcome.captures.camera_name!r}" if seen else ""
        self.report({'INFO'}, f"Tracked {outcome.captures.label} with {arm.name!r} (action {action.name!r}): "
                              f"{depth_summary(outcome)}{saved}{camera}")


classes = (ARTICULA_OT_track,)
