"""``articula.farm_submit`` / ``articula.farm_cancel``: track a long recording in chunks on a Flamenco
Manager from the Farm panel (docs/farm.md; ``./run farm track`` is the batch form).  Submit checks the
inputs, submits the job and follows it every :data:`POLL_SECONDS` (failed chunks are submitted again by
:class:`FarmRun`), writing the status into ``Scene.articula_farm``; Cancel stops it on the Manager."""
import time

import bpy

from ..addon.farm import panel_jobs
from ..addon.farm.panel_jobs import POLL_SECONDS, RUNS, poll_once
from ..solver.errors import ArticulaInputError
from ..solver.farm.flamenco import FarmError


class ARTICULA_OT_farm_submit(bpy.types.Operator):
    """Check the Farm panel's inputs, submit a chunked tracking job to the Flamenco Manager and follow it
    (status and chunks in the panel; failed chunks are submitted again)"""
    bl_idname = "articula.farm_submit"
    bl_label = "Submit to Farm"
    bl_options = {'REGISTER'}

    def _start(self, context):
        try:
            return panel_jobs.start_run(context.scene)
        except ArticulaInputError as exc:
            context.scene.articula_farm.status_text = str(exc).splitlines()[0]
            self.report({'ERROR'}, str(exc))
            return None

    def execute(self, context):
        run = self._start(context)
        if run is None:
            return {'CANCELLED'}
        self.report({'INFO'}, context.scene.articula_farm.status_text)
        panel_jobs.follow_with_timer(context.scene.name, run)
        return {'FINISHED'}

    def invoke(self, context, event):
        if context.window is None:
            return self.execute(context)
        self._run = self._start(context)
        if self._run is None:
            return {'CANCELLED'}
        self.report({'INFO'}, context.scene.articula_farm.status_text)
        self._scene, self._next = context.scene.name, time.monotonic() + POLL_SECONDS
        self._timer = context.window_manager.event_timer_add(POLL_SECONDS, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type != 'TIMER' or time.monotonic() < self._next:
            return {'PASS_THROUGH'}
        self._next = time.monotonic() + POLL_SECONDS
        ended, error = poll_once(self._scene, self._run)
        if not ended:
            return {'PASS_THROUGH'}
        context.window_manager.event_timer_remove(self._timer)
        if error:
            self.report({'ERROR'}, error)
            return {'CANCELLED'}
        if self._run.last is not None and self._run.last.job_status == "completed":
            self.report({'INFO'}, f"farm job {self._run.job_id} completed: {self._run.work.out}")
        return {'FINISHED'}


class ARTICULA_OT_farm_cancel(bpy.types.Operator):
    """Cancel the followed farm job on the Flamenco Manager (its running tasks are stopped)"""
    bl_idname = "articula.farm_cancel"
    bl_label = "Cancel Farm Job"
    bl_options = {'REGISTER'}

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.scene.name in RUNS

    def execute(self, context):
        name = context.scene.name
        run = RUNS.pop(name, None)
        if run is None:
            self.report({'ERROR'}, "no farm job is followed in this scene")
            return {'CANCELLED'}
        try:
            text = f"cancelled job {run.job_id}: {run.cancel()}"
        except FarmError as exc:
            RUNS[name] = run                 # still followed: the user may try again
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        context.scene.articula_farm.status_text = text
        self.report({'INFO'}, text)
        return {'FINISHED'}


classes = (ARTICULA_OT_farm_submit, ARTICULA_OT_farm_cancel)
