"""The Farm panel (docs/farm.md) without a Manager: its operators and scene state register with the
add-on; a submit to a Manager nobody listens on, or with a missing model, is refused with one message
naming the problem and changes nothing in the scene or on disk; the panel draws the followed job's
status, progress and one row per chunk (a recorder stands in for the UI layout in background mode).
Following a real job from the panel: tests/blender/farm/test_farm_track.py."""
import bpy
import pytest

from articula.sample_scenes.depth_bench import bench_recording

pytestmark = pytest.mark.usefixtures("cache_home")

NOBODY = "http://127.0.0.1:9"            # the discard port: nothing listens there


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    return bench_recording(tmp_path_factory.mktemp("depth") / "rec", subject_seed=0, resolution=(160, 120), frames=4)


def farm_inputs(scene, bench, tmp_path, **kw):
    state = scene.articula_farm
    state.manager_url, state.model, state.input_dir = NOBODY, bench["model_path"], bench["out_dir"]
    state.kind, state.out = 'DEPTH', str(tmp_path / "tracked.npz")
    for key, value in kw.items():
        setattr(state, key, value)
    return state


def test_operators_and_scene_state_are_registered():
    assert hasattr(bpy.ops.articula, "farm_submit") and hasattr(bpy.ops.articula, "farm_cancel")
    assert bpy.types.ARTICULA_PT_farm.bl_parent_id == "ARTICULA_PT_main"
    state = bpy.context.scene.articula_farm
    assert state.manager_url == "http://localhost:8080" and state.kind == 'DEPTH' and state.retries == 2
    assert (state.chunk, state.overlap, state.progress, len(state.chunks)) == (0, 0, 0.0, 0)


def test_the_pip_module_reports_no_online_access_and_is_not_refused(pkg):
    """bpy as a Python module: online_access False without a user choice; only --offline-mode refuses."""
    assert not bpy.app.online_access and not bpy.app.online_access_override and not bpy.app.binary_path
    assert pkg("addon.farm.panel_jobs").online_refusal() == ""


def test_an_unreachable_manager_is_named_and_nothing_changes(pkg, bench, tmp_path):
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_cube_add()
    before = sorted(ob.name for ob in bpy.data.objects)
    state = farm_inputs(scene, bench, tmp_path)
    with pytest.raises(RuntimeError, match=r"Flamenco Manager http://127\.0\.0\.1:9 unreachable"):
        bpy.ops.articula.farm_submit()
    assert sorted(ob.name for ob in bpy.data.objects) == before
    assert not list(tmp_path.iterdir())                   # no output, no chunk folder
    assert "unreachable" in state.status_text and state.job_id == ""
    assert scene.name not in pkg("addon.farm.panel_jobs").RUNS
    assert not bpy.ops.articula.farm_cancel.poll()        # nothing followed: Cancel is greyed out


@pytest.mark.parametrize("model,kind,match", [("", 'SCANS', "needs the person's model bundle"),
                                              ("missing.npz", 'DEPTH', "missing.npz")])
def test_a_missing_model_is_refused_before_the_manager(bench, tmp_path, model, kind, match):
    """Captures need a model (a depth recording without one starts from the template body)."""
    farm_inputs(bpy.context.scene, bench, tmp_path, model=str(tmp_path / model) if model else "", kind=kind)
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.articula.farm_submit()
    assert not (tmp_path / "tracked.npz").exists()


def test_the_panel_draws_the_job_and_its_chunks(pkg):
    status = pkg("solver.farm.follow").Status("abc123", "active", ["completed", "active", "queued"], "queued", 1,
                                              "job abc123 active: chunks 1 active, 1 completed, 1 queued")
    state = bpy.context.scene.articula_farm
    pkg("addon.farm.panel_state").show_status(state, status)
    assert [(c.name, c.status) for c in state.chunks] == [
        ("chunk 1", "completed"), ("chunk 2", "active"), ("chunk 3", "queued"), ("merge", "queued")]
    assert state.progress == pytest.approx(0.25)
    calls = []

    class Recorder:
        def __getattr__(self, name):
            if name in ("column", "row", "box"):
                return lambda **kw: self
            return lambda *args, **kw: calls.append((name, args, kw))

    class Panel:
        layout = Recorder()

    bpy.types.ARTICULA_PT_farm.draw(Panel(), bpy.context)
    props = [args[1] for name, args, _ in calls if name == "prop"]
    assert props == ["manager_url", "model", "input_dir", "kind", "camera", "out", "blend", "chunk", "overlap",
                     "retries"]
    assert [args[0] for name, args, _ in calls if name == "operator"] == ["articula.farm_submit",
                                                                          "articula.farm_cancel"]
    labels = [kw.get("text") for name, _, kw in calls if name == "label"]
    assert "Job abc123" in labels and labels[-8:] == ["chunk 1", "completed", "chunk 2", "active", "chunk 3",
                                                      "queued", "merge", "queued"]
    assert [kw["factor"] for name, _, kw in calls if name == "progress"] == [pytest.approx(0.25)]
