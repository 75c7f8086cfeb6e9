"""``articula.farm_submit`` / ``articula.farm_cancel``: track a long recording in chunks on a Flamenco
Manager from the Farm panel (docs/farm.md; ``./run farm track`` is the batch form).  Submit checks the
inputs, submits the job and follows it every :data:`POLL_SECONDS` (failed chunks are submitted again by
:class:`FarmRun`), writing the status into ``Scene.articula_farm``; Cancel stops it on the Manager."""
import time

import bpy

from ..addon.farm import inputs
from ..addon.farm.panel_state import show_status
from ..solver.errors import ArticulaInputError
from ..solver.farm.flamenco import FarmError, Manager
from ..solver.farm.follow import FarmRun

POLL_SECONDS = 2.0
TIMEOUT = 5.0                        # seconds per request: a poll blocks the interface at most this long
RUNS = {}                            # scene name -> the FarmRun followed for it (this session only)


def online_refusal() -> str:
    """Why Articula may not reach the network ('' when it may).  Blender's extension policy: respect
    ``bpy.app.online_access``.  The pip ``bpy`` module (no ``binary_path``) reports False without any
    user choice, so there only an explicit ``--offline-mode`` (``online_access_override``) refuses."""
    if bpy.app.online_access:
        return ""
    if getattr(bpy.app, "online_access_override", False):
        return "Blender was started in offline mode: start it without --offline-mode to reach the Flamenco Manager"
    if bpy.app.binary_path:
        return "online access is disabled: allow it in Preferences > System > Network to reach the Flamenco Manager"
    return ""


def start_run(scene) -> FarmRun:
    """Check the panel's inputs, submit the job and remember it in :data:`RUNS`; raises
    :class:`ArticulaInputError` (the Manager's failures are :class:`FarmError`) with what to fix."""
    refusal = online_refusal()
    if refusal:
        raise ArticulaInputError(refusal)
    if scene.name in RUNS:
        raise ArticulaInputError(f"job {RUNS[scene.name].job_id} is still followed: cancel it first")
    s, path = scene.articula_farm, bpy.path.abspath
    manager = Manager(s.manager_url, TIMEOUT)
    job = inputs.track_job(path(s.model) if s.model else "", path(s.input_dir), s.kind.lower(), path(s.out),
                           path(s.blend) if s.blend else "", s.chunk, s.overlap, camera=s.camera.strip())
    run = FarmRun(manager, job, s.retries)
    run.start()
    RUNS[scene.name] = run
    s.job_id, s.progress = run.job_id, 0.0
    s.status_text = f"submitted job {run.job_id} to {manager.url} ({job.count} chunks)"
    s.chunks.clear()
    return run


def poll_once(scene_name: str, run: FarmRun):
    """Poll ``run`` once and show it on the scene.  Returns ``(ended, error)``: ended when the job
    completed, failed for good, or is no longer followed (cancelled); ``error`` is '' or the message."""
    if RUNS.get(scene_name) is not run:
        return True, ""
    scene = bpy.data.scenes.get(scene_name)
    try:
        status = run.poll()
    except (ArticulaInputError, KeyError, TypeError, ValueError) as exc:
        RUNS.pop(scene_name, None)
        message = str(exc) if isinstance(exc, ArticulaInputError) else f"unexpected answer from the Manager: {exc!r}"
        if scene is not None:
            scene.articula_farm.status_text = message.splitlines()[0]
        _redraw()
        return True, message
    if scene is not None:
        show_status(scene.articula_farm, status)
    _redraw()
    if status.job_status == "completed":
        RUNS.pop(scene_name, None)
        return True, ""
    return False, ""


def _redraw() -> None:
    wm = bpy.context.window_manager
    for window in (wm.windows if wm else ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def _follow_with_timer(scene_name: str, run: FarmRun) -> None:
    """Follow ``run`` with an application timer (scripts; Blender without a window): errors go to the
    panel's status line and the console."""
    def tick():
        ended, error = poll_once(scene_name, run)
        if error:
            print(f"Articula farm: {error}")
        return None if ended else POLL_SECONDS
    bpy.app.timers.register(tick, first_interval=POLL_SECONDS)


class ARTICULA_OT_farm_submit(bpy.types.Operator):
    """Check the Farm panel's inputs, submit a chunked tracking job to the Flamenco Manager and follow it
    (status and chunks in the panel; failed chunks are submitted again)"""
    bl_idname = "articula.farm_submit"
    bl_label = "Submit to Farm"
    bl_options = {'REGISTER'}

    def _start(self, context):
        try:
            return start_run(context.scene)
        except ArticulaInputError as exc:
            context.scene.articula_farm.status_text = str(exc).splitlines()[0]
            self.report({'ERROR'}, str(exc))
            return None

    def execute(self, context):
        run = self._start(context)
        if run is None:
            return {'CANCELLED'}
        self.report({'INFO'}, context.scene.articula_farm.status_text)
        _follow_with_timer(context.scene.name, run)
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
