"""Long work without freezing Blender: a mixin for operators whose heavy part runs in a worker thread.

An operator using :class:`JobOperator` splits its work in three parts:

``prepare(context) -> work``
    Main thread.  Reads everything it needs from bpy, validates it (raise ``ArticulaInputError``)
    and returns ``work(progress) -> result``, a callable that must NOT touch bpy.
``work(progress)``
    Worker thread (or the calling thread in scripts/background mode).  Calls
    ``progress(fraction, text)`` now and then; that call raises ``Cancelled`` once the user pressed Esc.
``finish(context, result)``
    Main thread.  Creates the scene data.  Runs inside :func:`scene_guard`, so any exception here
    removes every datablock created so far and the scene is left as it was.

``execute`` (scripts, ``bpy.ops.articula.x()``, background mode) runs all three synchronously and
prints progress in background mode.  ``invoke`` from the UI starts the worker thread and a modal
timer that shows progress in the status bar and the window-manager progress indicator; Esc cancels
the work and nothing is changed, even when it had already finished.
"""
from __future__ import annotations

import contextlib
import sys
import threading
import time

import bpy

from ..solver.errors import ArticulaInputError, Cancelled

# Datablock collections a feature may create; scene_guard removes new members on failure.
_GUARDED = ("objects", "meshes", "armatures", "actions", "cameras", "collections", "materials",
            "images", "node_groups", "pointclouds", "curves", "texts")


def _snapshot():
    return {name: {id_.as_pointer() for id_ in getattr(bpy.data, name)}
            for name in _GUARDED if hasattr(bpy.data, name)}


def _animation_state(ob):
    """``(active action, slot, {NLA track pointer: {strip pointers}})`` of ``ob``, None without animation data."""
    ad = ob.animation_data
    if ad is None:
        return None
    return (ad.action, getattr(ad, "action_slot", None),
            {t.as_pointer(): {s.as_pointer() for s in t.strips} for t in ad.nla_tracks})


def _restore_animation(ob, state) -> None:
    """Put ``ob``'s animation data back to ``state`` (:func:`_animation_state`): new NLA tracks and strips
    removed, the active action and its slot reassigned."""
    ad = ob.animation_data
    if ad is None or state == _animation_state(ob):
        return
    if state is None:
        ob.animation_data_clear()
        return
    action, slot, tracks = state
    for track in list(ad.nla_tracks):
        old = tracks.get(track.as_pointer())
        if old is None:
            ad.nla_tracks.remove(track)
            continue
        for strip in [s for s in track.strips if s.as_pointer() not in old]:
            track.strips.remove(strip)
    if ad.action != action:
        ad.action = action
    if slot is not None and ad.action_slot != slot:
        ad.action_slot = slot


@contextlib.contextmanager
def scene_guard():
    """If the block raises (any exception, not only bad input): remove every datablock created inside it,
    put the existing objects' animation (active action, NLA tracks and strips) and the current frame back
    as they were, and re-raise."""
    before = _snapshot()
    animation = [(ob, _animation_state(ob)) for ob in bpy.data.objects]
    frame = bpy.context.scene.frame_current if bpy.context.scene else None
    try:
        yield
    except BaseException:
        for ob, state in animation:
            _restore_animation(ob, state)
        for name, old in before.items():
            coll = getattr(bpy.data, name)
            for id_ in [i for i in coll if i.as_pointer() not in old]:
                coll.remove(id_)
        if frame is not None and bpy.context.scene:
            bpy.context.scene.frame_current = frame
        raise


class Progress:
    """Thread-safe progress state shared between the worker and the UI.

    Calling it, ``progress(fraction in [0, 1], text)``, records the state and raises
    ``Cancelled`` when :meth:`cancel` was called.
    """

    def __init__(self, label: str, echo: bool = False):
        self.label = label
        self.fraction = 0.0
        self.text = ""
        self._cancel = threading.Event()
        self._echo = echo
        self._last_echo = 0.0

    def __call__(self, fraction: float, text: str = "") -> None:
        self.fraction = min(max(float(fraction), 0.0), 1.0)
        if text:
            self.text = text
        if self._echo and (time.monotonic() - self._last_echo > 1.0 or self.fraction >= 1.0):
            self._last_echo = time.monotonic()
            print(f"{self.label}: {100 * self.fraction:5.1f}% {self.text}", file=sys.stderr, flush=True)
        if self._cancel.is_set():
            raise Cancelled(self.label)

    def cancel(self) -> None:
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()


class JobOperator:
    """Mixin for ``bpy.types.Operator`` subclasses; see the module docstring."""

    job_label = "Articula"

    # -- to implement -------------------------------------------------------------------------
    def prepare(self, context):
        raise NotImplementedError

    def finish(self, context, result):
        raise NotImplementedError

    # -- synchronous path ---------------------------------------------------------------------
    def execute(self, context):
        try:
            work = self.prepare(context)
            result = work(Progress(self.job_label, echo=bpy.app.background))
            with scene_guard():
                self.finish(context, result)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        except Cancelled:
            self.report({'WARNING'}, f"{self.job_label}: cancelled, nothing was changed")
            return {'CANCELLED'}
        return {'FINISHED'}

    # -- interactive path ---------------------------------------------------------------------
    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        started = self.start_job(context)
        if started == {'RUNNING_MODAL'}:
            wm = context.window_manager
            self._timer = wm.event_timer_add(0.1, window=context.window)
            wm.progress_begin(0, 100)
            wm.modal_handler_add(self)
        return started

    def start_job(self, context):
        """Prepare on the main thread and start the worker thread; ``{'RUNNING_MODAL'}``, or
        ``{'CANCELLED'}`` after reporting bad input.  :meth:`modal` then follows the worker."""
        try:
            work = self.prepare(context)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self._timer = None
        self._progress = Progress(self.job_label)
        self._outcome = {}
        self._thread = threading.Thread(target=self._run, args=(work,), daemon=True)
        self._thread.start()
        return {'RUNNING_MODAL'}

    def _run(self, work):
        try:
            self._outcome["result"] = work(self._progress)
        except BaseException as exc:  # handed to the main thread
            self._outcome["error"] = exc

    def modal(self, context, event):
        if event.type == 'ESC':
            self._progress.cancel()
            return {'RUNNING_MODAL'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        context.window_manager.progress_update(int(100 * self._progress.fraction))
        if context.workspace:
            context.workspace.status_text_set(
                f"{self.job_label}: {100 * self._progress.fraction:.0f}% {self._progress.text} (Esc to cancel)")
        if self._thread.is_alive():
            return {'RUNNING_MODAL'}
        return self._end(context)

    def _end(self, context):
        """The worker has ended: report its outcome; build the scene data unless it failed or Esc was
        pressed (also when Esc came after the work was done: nothing is changed then either)."""
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace:
            context.workspace.status_text_set(None)
        error = self._outcome.get("error")
        if isinstance(error, Cancelled) or self._progress.cancelled:
            self.report({'WARNING'}, f"{self.job_label}: cancelled, nothing was changed")
            return {'CANCELLED'}
        if isinstance(error, ArticulaInputError):
            self.report({'ERROR'}, str(error))
            return {'CANCELLED'}
        try:
            if error is not None:
                raise error
            with scene_guard():
                self.finish(context, self._outcome["result"])
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        except Exception as exc:  # the scene guard has removed what finish made
            self.report({'ERROR'}, f"{self.job_label} failed: {type(exc).__name__}: {exc}")
            return {'CANCELLED'}
        return {'FINISHED'}
