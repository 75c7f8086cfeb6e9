"""``articula.track``: track a sequence of unregistered captures with a person's model and bake the motion
on the rig, which then plays over the captures, with per-frame residual curves and error colours on the
captures.

Input: the model of the Articula rig named ``rig`` (empty: the active or a selected rig), or of the
bundle file ``bundle``; the captures of the scan-sequence or point-cloud object named ``captures``
(empty: the one selected).  The work is in :mod:`addon.track`; the settings' defaults come from
:class:`solver.track.options.TrackOptions`.
"""
import os
from dataclasses import replace

import bpy

from ..addon.jobs import JobOperator
from ..addon.rig import reader
from ..addon.track import inputs, result, solve
from ..addon.track.report import summary_text
from ..solver.errors import ArticulaInputError
from ..solver.track.options import TrackOptions

_DEFAULT = TrackOptions()
ADAPT_ITEMS = (('AUTO', "Auto", "Adapt the rest mesh and joints when the tracked range is long enough"),
               ('ON', "On", "Always adapt the model to the recording"),
               ('OFF', "Off", "Keep the model as it is"))
PRIOR_ITEMS = (('AUTO', "Auto", "The model's own training poses when it has some, else the generic human prior"),
               ('MODEL', "Model's Poses", "Learn the pose prior from the poses the model was trained on"),
               ('GENERIC', "Generic Human", "The generic human pose prior shipped with Articula"),
               ('NONE', "None", "No pose prior"))


class ARTICULA_OT_track(JobOperator, bpy.types.Operator):
    """Track unregistered captures (a scan-sequence or point-cloud object) with a person's rig: one pose
    per frame baked as an action, residual curves, error colours on the captures"""
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
        for prop in ("adapt", "prior", "temporal", "fit_scale", "max_points"):
            col.prop(self, prop)
        sub = col.row()
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
        options = TrackOptions(adapt=self.adapt.lower(), prior=self.prior.lower(), temporal=self.temporal,
                               fit_scale=self.fit_scale, max_points=self.max_points).validate()
        out = bpy.path.abspath(self.output_bundle) if self.output_bundle else ""
        result.check_output_path(out)
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
        ob = inputs.find_captures(context, self.captures)
        model_input.matrix = inputs.solve_matrix(model_input, ob)
        captures = inputs.captures_from_object(ob, model_input.matrix)
        if self.use_frame_range:
            first, last = self.frame_first - captures.frame_start, self.frame_last - captures.frame_start
            n = len(captures.names)
            if not 0 <= first <= last < n:
                raise ArticulaInputError(f"Frame Range {self.frame_first}..{self.frame_last} lies outside the "
                                         f"captures' frames {captures.frame_start}..{captures.frame_start + n - 1}")
            options = replace(options, frames=(first, last + 1)).validate()
        self._output = out

        def work(progress):
            progress(0.0, "reading captures")
            return solve.track(model_input, captures, options, progress)
        return work

    def finish(self, context, outcome):
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


classes = (ARTICULA_OT_track,)
