"""The long-work operator mixin: synchronous execute, progress, cancellation, and roll-back of
half-created scene data."""
import bpy
import pytest


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

    bpy.utils.register_class(ARTICULA_OT_test_job)
    yield ARTICULA_OT_test_job
    bpy.utils.unregister_class(ARTICULA_OT_test_job)


def test_execute_runs_work_and_finish(job_operator):
    assert bpy.ops.articula.test_job(mode="ok") == {'FINISHED'}
    assert "made_42" in bpy.data.objects


@pytest.mark.parametrize("mode, message", [("bad_input", "bad input named here"),
                                            ("fail_in_finish", "failed half-way")])
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
