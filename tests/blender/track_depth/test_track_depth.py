"""articula.track on a depth recording (the depth-camera tracker): with the subject's rig (moved in the
scene: the solve frame is its object space) the action has one key per frame and the rig's joints, as
Blender shows them, lie within a few cm of the true major joints mapped into Blender's world; without a
rig the built-in template is tracked and built as a new rig; the recording's camera becomes the scene
camera; Esc and bad input leave the scene as it was; Captures keeps the capture tracker on such objects.

Data: a tiny synthetic recording (sample_scenes.depth_bench: a MakeHuman subject turning in front of a
Kinect v1 at 160x120, 4 frames, intrinsics.json with cam_to_world), imported with articula.import_depth
(whose world is the fitted floor's).  The real tracker runs (about a second).
"""
import json

import bpy
import numpy as np
import pytest

from articula.sample_scenes.depth_bench import bench_recording
from articula.solver.track_depth.options import DepthTrackOptions
from ..rig_helpers import key_frames

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

N = 4
FRAME_START = 3


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    return bench_recording(tmp_path_factory.mktemp("depth") / "rec", subject_seed=0, resolution=(160, 120), frames=N)


def import_recording(folder, frame_start=FRAME_START):
    assert bpy.ops.articula.import_depth(directory=str(folder), frame_start=frame_start) == {'FINISHED'}
    ob = bpy.context.view_layer.objects.active
    assert ob.articula.kind == 'POINT_CLOUD_SEQUENCE' and ob.parent.type == 'CAMERA'
    return ob


def build_rig(path, name="Subject"):
    assert bpy.ops.articula.build_rig(filepath=str(path), name=name) == {'FINISHED'}
    return bpy.data.objects[name]


def select(*obs):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in obs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = obs[0] if obs else None


def moved():
    """A rotation of 30 deg about Z and a shift: where a rig is put in the scene."""
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    return np.array([[c, -s, 0, 1.0], [s, c, 0, 2.0], [0, 0, 1, 0.1], [0, 0, 0, 1]])


def true_joints_in_blender(bench, ob):
    """The true major joints (N, 14, 3) in Blender's world: intrinsics world -> camera (inv(cam_to_world))
    -> Blender world (the depth object's matrix: sensor frame -> world)."""
    m = np.array(ob.matrix_world) @ np.linalg.inv(bench["cam_to_world"])
    return bench["joints"] @ m[:3, :3].T + m[:3, 3]


def rig_joints(arm, bench, frames):
    """The heads of the major joints' bones of ``arm`` in Blender's world at ``frames`` (as Blender poses them)."""
    names = [bench["model"].skeleton.names[b] for b in bench["joint_bones"]]
    out = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        m = np.array(arm.matrix_world)
        heads = np.array([tuple(arm.pose.bones[n].head) for n in names])
        out.append(heads @ m[:3, :3].T + m[:3, 3])
    return np.array(out)


def scene_state():
    scene = bpy.context.scene
    return ({k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "armatures", "actions", "collections")},
            scene.frame_start, scene.frame_end, scene.frame_current, scene.camera.name if scene.camera else None,
            {o.name: (tuple(o.matrix_world.translation), o.hide_get()) for o in bpy.data.objects},
            {o.name: o.animation_data.action.name for o in bpy.data.objects
             if o.animation_data is not None and o.animation_data.action is not None})


def test_rig_tracks_the_recording_and_plays_over_it(pkg, bench):
    """The subject's rig, moved away from the origin (tracking happens in its object space), tracked over
    the imported recording: one key per frame on the recording's frames, the joints within a few cm of the
    true ones in Blender's world, the report and residual curve on the armature, the camera as scene camera."""
    ob = import_recording(bench["out_dir"])
    other = bpy.data.objects.new("Other Camera", bpy.data.cameras.new("Other Camera"))
    bpy.context.scene.collection.objects.link(other)
    bpy.context.scene.camera = other
    rig = build_rig(bench["model_path"])
    from mathutils import Matrix
    rig.matrix_world = Matrix(moved().tolist())
    select(rig, ob)
    assert bpy.ops.articula.track() == {'FINISHED'}
    assert key_frames(pkg, rig) == {tuple(range(FRAME_START, FRAME_START + N))}
    assert rig.animation_data.action.name == f"Subject tracked {ob.name}"
    np.testing.assert_allclose(np.array(rig.matrix_world), moved(), atol=1e-6)      # the rig stays where it was
    err = np.linalg.norm(rig_joints(rig, bench, range(FRAME_START, FRAME_START + N))
                         - true_joints_in_blender(bench, ob), axis=-1)
    assert np.median(err) < 0.04 and np.mean(err < 0.06) > 0.75, np.round(100 * err, 1)
    report = json.loads(rig["articula_track_report"])
    assert report["format"] == "articula-depth-track-report/1" and report["tracker"] == DepthTrackOptions().tracker
    assert report["template"] is False and report["model"]["source"] == "rig 'Subject'"
    assert report["input"]["frames"] == N and len(report["per_frame"]) == N
    assert bpy.context.scene.camera == ob.parent                  # seen through the recording's camera
    fcs = [fc for fc in pkg("addon.compat").object_action_fcurves(rig, rig.animation_data.action)
           if fc.data_path == '["articula_residual_mean_mm"]']
    means = [f["mean_mm"] for f in report["per_frame"]]
    np.testing.assert_allclose([fcs[0].evaluate(FRAME_START + k) for k in range(N)], means, rtol=1e-5)
    assert len([o for o in bpy.data.objects if o.type == 'ARMATURE' and o.articula.kind == 'RIG_ARMATURE']) == 1


def test_without_a_rig_the_template_is_tracked(pkg, bench, tmp_path):
    """Only the depth object selected: the built-in template body is tracked (adapted to the person), built
    as a new rig at the origin over the points, on a frame range, and saved to a bundle."""
    ob = import_recording(bench["out_dir"])
    select(ob)
    out = str(tmp_path / "tracked.npz")
    assert bpy.ops.articula.track(use_frame_range=True, frame_first=FRAME_START + 1, frame_last=FRAME_START + 3,
                                  output_bundle=out) == {'FINISHED'}
    arm = bpy.data.objects["Template Person"]
    template = pkg("solver.track_depth.template").load_template().base
    names = pkg("addon.rig.reader").control_names(arm)
    assert names == list(template.skeleton.names)
    np.testing.assert_allclose(np.array(arm.matrix_world), np.eye(4), atol=1e-7)
    assert key_frames(pkg, arm) == {tuple(range(FRAME_START + 1, FRAME_START + 4))}
    err = np.linalg.norm(rig_joints(arm, bench, range(FRAME_START + 1, FRAME_START + 4))
                         - true_joints_in_blender(bench, ob)[1:], axis=-1)
    assert np.median(err) < 0.10, np.round(100 * err, 1)     # the template is not the subject: looser
    report = json.loads(arm["articula_track_report"])
    assert report["template"] is True and report["input"]["first_frame"] == 1 and report["input"]["tracked"] == 3
    bundle = pkg("solver.formats.bundle").load_bundle(out)
    assert len(bundle.poses) == 3 and list(bundle.model.skeleton.names) == names
    assert bundle.provenance["template"] is True and bundle.provenance["first_frame"] == 1
    assert bpy.context.scene.camera == ob.parent


def test_capture_tracker_still_runs_on_a_depth_object_when_asked(pkg, bench, monkeypatch):
    """Tracker "Captures" sends a depth object to the capture tracker (which needs a rig): without one it
    says so instead of using the template."""
    ob = import_recording(bench["out_dir"])
    select(ob)
    with pytest.raises(RuntimeError, match="no rig: make an Articula rig active"):
        bpy.ops.articula.track(method='CAPTURES')


def test_cancel_leaves_scene_unchanged(pkg, bench, monkeypatch):
    """Esc while frame 2 is tracked: nothing created, no action changed, the scene camera kept."""
    jobs = pkg("addon.jobs")
    ob = import_recording(bench["out_dir"])
    rig = build_rig(bench["model_path"])
    select(rig, ob)
    bpy.context.scene.camera = None
    seen = []

    class CancelAtFrameTwo(jobs.Progress):
        def __call__(self, fraction, text=""):
            seen.append(text)
            if "frame 2 of" in text:
                self.cancel()
            super().__call__(fraction, text)

    monkeypatch.setattr(jobs, "Progress", CancelAtFrameTwo)
    before = scene_state()
    assert bpy.ops.articula.track() == {'CANCELLED'}
    assert scene_state() == before and bpy.context.scene.camera is None
    assert any(t.startswith(f"frame 1 of {N}") for t in seen) and "done" not in seen


@pytest.mark.parametrize("case, message", [
    ("start_from_rig", "Start From Rig's Pose is for scans and point clouds"),
    ("scaled_rig", "is scaled, sheared or mirrored"),
    ("depth_on_scans", "is a scan sequence; the depth-camera tracker needs a depth recording"),
    ("range", r"Frame Range 1..4 lies outside the captures' frames 3..6"),
    ("missing_bundle", "nowhere.npz: no such bundle file"),
])
def test_bad_input_is_refused_and_leaves_scene_unchanged(pkg, bench, tmp_path, case, message):
    ob = import_recording(bench["out_dir"])
    rig = build_rig(bench["model_path"])
    select(rig, ob)
    kwargs = {}
    if case == "start_from_rig":
        kwargs["start_from_rig"] = True
    elif case == "scaled_rig":
        rig.scale = (2, 2, 2)
    elif case == "depth_on_scans":
        from articula.sample_scenes.mesh_files import SequenceWriter
        model = bench["model"]
        folder = tmp_path / "scans"
        folder.mkdir()
        for k in range(2):
            SequenceWriter(model.faces, "ply").write(str(folder / f"s{k}.ply"), model.rest_vertices)
        assert bpy.ops.articula.import_scans(directory=str(folder)) == {'FINISHED'}
        scans = bpy.context.view_layer.objects.active
        select(rig, scans)
        kwargs["method"] = 'DEPTH'
    elif case == "range":
        kwargs.update(use_frame_range=True, frame_first=1, frame_last=4)
    elif case == "missing_bundle":
        kwargs["bundle"] = str(tmp_path / "nowhere.npz")
    before = scene_state()
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.articula.track(**kwargs)
    assert scene_state() == before


def test_person_option_reaches_the_solver(pkg, bench, solver_options):
    """The operator's Person (whom to start on with several people in view) is the solver's option; a
    stopped run leaves the scene as it was."""
    ob = import_recording(bench["out_dir"])
    select(ob)
    before = scene_state()
    assert bpy.ops.articula.track(person='NEAREST') == {'CANCELLED'}
    assert [o.person for o in solver_options] == ["nearest"] and scene_state() == before
