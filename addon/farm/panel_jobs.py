"""Following a farm job from the Farm panel (docs/farm.md): the submit checks Blender's online access and
the panel's inputs and submits (:func:`start_run`); each poll writes the job's status into
``Scene.articula_farm`` (:func:`poll_once`), driven by the submit operator's modal timer or, without a
window, by an application timer (:func:`follow_with_timer`).  :data:`RUNS` holds the followed
:class:`solver.farm.follow.FarmRun` per scene for this session."""
import bpy

from ...solver.errors import ArticulaInputError
from ...solver.farm.flamenco import Manager
from ...solver.farm.follow import FarmRun
from . import inputs
from .panel_state import show_status

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
        redraw()
        return True, message
    if scene is not None:
        show_status(scene.articula_farm, status)
    redraw()
    if status.job_status == "completed":
        RUNS.pop(scene_name, None)
        return True, ""
    return False, ""


def redraw() -> None:
    wm = bpy.context.window_manager
    for window in (wm.windows if wm else ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def follow_with_timer(scene_name: str, run: FarmRun) -> None:
    """Follow ``run`` with an application timer (scripts; Blender without a window): errors go to the
    panel's status line and the console."""
    def tick():
        ended, error = poll_once(scene_name, run)
        if error:
            print(f"Articula farm: {error}")
        return None if ended else POLL_SECONDS
    bpy.app.timers.register(tick, first_interval=POLL_SECONDS)
