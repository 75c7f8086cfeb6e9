"""The long-work operator mixin: synchronous execute, progress, cancellation, and roll-back of
half-created scene data (also on unexpected errors); the modal path (worker thread, timer events, Esc)
driven on a real operator."""
import os
import time

import bpy
import numpy as np
import pytest

from articula.sample_scenes.depth_scene import floor_box_scene
from articula.solver.depth import camera
from articula.solver.formats.bundle import save_bundle
from articula.solver.formats.png16 import write_png16
from articula.solver.rig.model import Poses
from articula.solver.track_depth.template import TEMPLATE_PATH, load_template


@pytest.fixture
def job_operator(pkg):
    jobs = pkg("addon.jobs")
    errors = pkg("solver.errors")

    class ARTICULA_OT_test_job(jobs.JobOperator, bpy.types.Operator):
        bl_idname = "articula.test_job"
        bl_label = "Test Job"
        mode: bpy.props.StringProperty(default="ok")

        def prepare(self, context):
            if self.mode == "bad_input":
                raise errors.ArticulaInputError("bad input named here")
            mode = self.mode

            def work(progress):
                for i in range(5):
                    progress(i / 5, f"step {i}")
                    if mode == "cancel" and i == 2:
                        progress.cancel()
                return 42
            return work

        def finish(self, context, result):
            me = bpy.data.meshes.new(f"made_{result}")
            ob = bpy.data.objects.new(f"made_{result}", me)
            context.scene.collection.objects.link(ob)
            if self.mode == "fail_in_finish":
                raise errors.ArticulaInputError("failed half-way")
            if self.mode == "crash_in_finish":
                raise ZeroDivisionError("an unexpected error half-way")

    bpy.utils.register_class(ARTICULA_OT_test_job)
    yield ARTICULA_OT_test_job
    bpy.utils.unregister_class(ARTICULA_OT_test_job)


def test_execute_runs_work_and_finish(job_operator):
    assert bpy.ops.articula.test_job(mode="ok") == {'FINISHED'}
    assert "made_42" in bpy.data.objects


@pytest.mark.parametrize("mode, message", [("bad_input", "bad input named here"),
                                            ("fail_in_finish", "failed half-way"),
                                            ("crash_in_finish", "an unexpected error half-way")])
def test_errors_are_reported_and_leave_scene_untouched(job_operator, mode, message):
    before = (len(bpy.data.objects), len(bpy.data.meshes))
    # An ERROR report makes bpy.ops raise RuntimeError carrying the message (scripts see it).
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.articula.test_job(mode=mode)
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == before


def test_cancel_leaves_scene_untouched(job_operator):
    before = (len(bpy.data.objects), len(bpy.data.meshes))
    assert bpy.ops.articula.test_job(mode="cancel") == {'CANCELLED'}
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == before


def test_progress_clamps_and_cancels(pkg):
    jobs = pkg("addon.jobs")
    errors = pkg("solver.errors")
    p = jobs.Progress("x")
    p(1.7, "over")
    assert p.fraction == 1.0 and p.text == "over"
    p.cancel()
    with pytest.raises(errors.Cancelled):
        p(0.5)


def datablocks():
    return {name: {i.as_pointer() for i in getattr(bpy.data, name)}
            for name in ("objects", "meshes", "armatures", "actions", "collections", "materials", "node_groups")}


@pytest.fixture
def bundle(tmp_path):
    """A model bundle with 3 poses: the template body (the rig, its mesh and an action to build)."""
    assert os.path.isfile(TEMPLATE_PATH), f"missing fixture {TEMPLATE_PATH}"
    model = load_template().base
    bones = model.skeleton.num_bones
    rotations = np.zeros((3, bones, 4))
    rotations[..., 0] = 1.0
    rotations[1:, 1:, :] = [np.cos(0.1), np.sin(0.1), 0.0, 0.0]
    path = str(tmp_path / "body.npz")
    save_bundle(path, model, Poses(rotations, np.zeros((3, 3)), np.ones(3)))
    return path


def test_unexpected_error_in_a_real_finish_removes_what_it_made(pkg, monkeypatch, bundle):
    """articula.build_rig builds the whole rig and bakes its poses, then a real function it calls last
    raises."""
    reader = pkg("addon.rig.reader")

    def broken(*args, **kwargs):
        raise MemoryError("out of memory while reporting")
    monkeypatch.setattr(reader, "control_names", broken)
    before = datablocks()
    with pytest.raises(RuntimeError, match="out of memory while reporting"):
        bpy.ops.articula.build_rig(filepath=bundle, name="Body")
    assert datablocks() == before


class Event:
    """A window event as ``modal`` sees it (only its type is read)."""
    def __init__(self, type_):
        self.type = type_


def modal_operator(base, idname):
    """A copy of the real operator class ``base`` (its bases, methods and properties; not a subclass: registering
    and unregistering a subclass of a registered operator unbinds the real one from Blender) whose ``execute``
    runs JobOperator's interactive path as the window manager runs it: the worker thread started by
    ``start_job``, then ``modal`` called with the events of the ``events`` property (e.g. "ESC") and timer
    events until it ends; ``outcome`` records how the worker ended.  (Background Blender has no window to run a
    modal handler.)"""

    def execute(self, context):
        state = self.start_job(context)
        for kind in filter(None, self.events.split(",")):
            state = self.modal(context, Event(kind))
        while state & {'RUNNING_MODAL', 'PASS_THROUGH'}:
            time.sleep(0.01)
            state = self.modal(context, Event('TIMER'))
        assert not self._thread.is_alive()
        type(self).outcome = dict(self._outcome)
        return state

    body = {k: v for k, v in base.__dict__.items() if k not in ("bl_rna", "__dict__", "__weakref__")}
    body["__annotations__"] = {**base.__dict__.get("__annotations__", {}),
                               "events": bpy.props.StringProperty(options={'SKIP_SAVE'})}
    body.update(bl_idname=idname, execute=execute, outcome={})
    return type("ARTICULA_OT_" + idname.split(".")[1], base.__bases__, body)


@pytest.fixture
def modal_ops(pkg):
    """bpy.ops callables of build_rig and import_depth driven through the modal path."""
    classes = [modal_operator(pkg("operators.build_rig").ARTICULA_OT_build_rig, "articula.test_modal_build_rig"),
               modal_operator(pkg("operators.import_depth").ARTICULA_OT_import_depth,
                              "articula.test_modal_import_depth")]
    for cls in classes:
        bpy.utils.register_class(cls)
    yield {"build_rig": (bpy.ops.articula.test_modal_build_rig, classes[0]),
           "import_depth": (bpy.ops.articula.test_modal_import_depth, classes[1])}
    for cls in classes:
        bpy.utils.unregister_class(cls)


def test_modal_build_rig_builds_and_esc_cancels(modal_ops, bundle):
    """Esc pressed while the bundle loads (or right after: nothing is built then either)."""
    op, _ = modal_ops["build_rig"]
    before = datablocks()
    assert op(filepath=bundle, name="Body", events="ESC") == {'CANCELLED'}
    assert datablocks() == before
    assert op(filepath=bundle, name="Body", events="MOUSEMOVE") == {'FINISHED'}
    made = {name: ids - before[name] for name, ids in datablocks().items()}
    assert made["objects"] and made["meshes"] and made["armatures"] and made["actions"]


def depth_recording(folder, frames=20):
    intr = camera.Intrinsics(160, 120, 140.0, 131.0, 84.3, 55.7)
    os.makedirs(folder)
    camera.save_intrinsics(os.path.join(folder, "intrinsics.json"), intr)
    for k in range(frames):
        x = -0.5 + k / frames
        depth, _, _ = floor_box_scene(intr, box=((x - .2, 2.2, 0), (x + .2, 2.6, .8)))
        write_png16(os.path.join(folder, f"depth_{k:04d}.png"), (depth * 1000).round().astype(np.uint16))
    return folder


def test_modal_import_depth_esc_stops_the_worker(modal_ops, tmp_path, pkg):
    """Esc pressed as the worker starts reading the frames: the worker stops (Cancelled) and nothing is
    made, no cache file either; without Esc the same import builds its objects."""
    op, cls = modal_ops["import_depth"]
    folder = depth_recording(str(tmp_path / "rec"))
    cache = str(tmp_path / "cache" / "rec.npz")
    before = datablocks()
    assert op(directory=folder, cache_file=cache, events="ESC") == {'CANCELLED'}
    assert isinstance(cls.outcome.get("error"), pkg("solver.errors").Cancelled)
    assert datablocks() == before and not os.path.exists(cache)
    assert op(directory=folder, cache_file=cache, events="") == {'FINISHED'}
    assert "result" in cls.outcome and datablocks()["objects"] - before["objects"] and os.path.exists(cache)
