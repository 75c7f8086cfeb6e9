"""articula.track: tracking an imported (unregistered) scan sequence with a rig or a bundle, the action on
the captures' frames, the residual curves, the error colours that follow the frame, bad input and
cancellation leaving the scene unchanged.

Data: the tube body (456 vertices, 19 bones, 1 cm random bumps) in a smooth motion, posed by the solver's hybrid skin, with
1 mm noise and 10 % of the triangles dropped per frame (so the topology changes), written as PLY files and
imported with ``articula.import_scans``.  Tests marked "stub" replace the tracker by one that returns the
true poses, to check the Blender side exactly; the others run the real pipeline (prior off, no temporal
pass, no adaptation: a few seconds).
"""
import json
import os
import re

import bpy
import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.sample_scenes.mesh_files import SequenceWriter
from articula.solver.formats.bundle import save_bundle
from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import hybrid_skin
from ..rig_helpers import key_frames

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

N = 5
FRAME_START = 3
FAST = dict(adapt='OFF', prior='NONE', temporal=False)


@pytest.fixture(scope="module")
def truth():
    """(model, poses (N frames), unregistered captures [(points, triangles)])."""
    return make_truth(N)


def make_truth(n, seed=0, bumps=0.01):
    """The tube body with random ``bumps`` (m) on its rest vertices (so a tube's twist shows in its surface:
    the plain tubes' hexagonal cross-section lets independent runs settle on twist-equivalent poses), a
    smooth motion of ``n`` frames (one whose legs do not pass through each other: the truth-free checks
    would call such frames lost) and its noisy captures with changing topology."""
    model = synthetic.tube_body(rings=4, segments=6)
    model.rest_vertices += np.random.default_rng(7).normal(scale=bumps, size=model.rest_vertices.shape)
    target = quat_to_rotvec(synthetic.random_poses(1, model.skeleton.num_bones, seed=3, max_angle=0.5).rotations[0])
    t = np.linspace(0, 1, n)
    poses = Poses(rotvec_to_quat(t[:, None, None] * target[None]), np.outer(t, [0.05, 0.02, 0.0]), np.ones(n))
    rng = np.random.default_rng(seed)
    captures = []
    for verts in hybrid_skin(model, poses):
        faces = model.faces[rng.random(len(model.faces)) > 0.1]
        used = np.unique(faces)
        remap = np.full(len(verts), -1)
        remap[used] = np.arange(len(used))
        captures.append((verts[used] + rng.normal(scale=0.001, size=(len(used), 3)), remap[faces]))
    return model, poses, captures


def write_captures(folder, captures):
    os.makedirs(folder, exist_ok=True)
    for k, (pts, tris) in enumerate(captures):
        SequenceWriter(tris, "ply").write(os.path.join(folder, f"scan_{k:02d}.ply"), pts)
    return str(folder)


def import_captures(tmp_path, captures, matrix=None, name="scans"):
    folder = write_captures(tmp_path / name, captures)
    assert bpy.ops.articula.import_scans(directory=folder, frame_start=FRAME_START) == {'FINISHED'}
    ob = bpy.context.view_layer.objects.active
    assert not ob.articula.registered
    if matrix is not None:
        from mathutils import Matrix
        ob.matrix_world = Matrix(np.asarray(matrix).tolist())
    return ob


def build_rig(tmp_path, model, poses=None, name="Person"):
    path = str(tmp_path / f"{name}.npz")
    save_bundle(path, model, poses)
    assert bpy.ops.articula.build_rig(filepath=path, name=name) == {'FINISHED'}
    return bpy.data.objects[name], path


def moved():
    """A rotation of 30 deg about Z and a shift: where the capture object is put in the scene."""
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    return np.array([[c, -s, 0, 1.0], [s, c, 0, 2.0], [0, 0, 1, 0.1], [0, 0, 0, 1]])


def world_points(ob):
    """The capture object's shown frame in world coordinates."""
    me = ob.data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    m = np.array(ob.matrix_world)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def evaluated_world(pkg, ob):
    m = np.array(ob.matrix_world)
    return pkg("addon.scene.mesh_io").evaluated_positions(ob) @ m[:3, :3].T + m[:3, 3]


def scene_state():
    return ({k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "armatures", "actions", "collections")},
            bpy.context.scene.frame_start, bpy.context.scene.frame_end, bpy.context.scene.frame_current,
            {o.name: (tuple(o.matrix_world.translation), o.hide_get()) for o in bpy.data.objects},
            {o.name: o.animation_data.action.name for o in bpy.data.objects
             if o.animation_data is not None and o.animation_data.action is not None})


def select(*obs):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in obs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = obs[0] if obs else None


def error_values(ob):
    attr = ob.data.attributes.get("articula_error_mm")
    if attr is None:
        return None
    v = np.empty(len(attr.data), np.float32)
    attr.data.foreach_get("value", v)
    return v


def fcurve_values(pkg, arm, prop, frames):
    fcs = [fc for fc in pkg("addon.compat").object_action_fcurves(arm, arm.animation_data.action)
           if fc.data_path == f'["{prop}"]']
    assert len(fcs) == 1
    return np.array([fcs[0].evaluate(f) for f in frames])


# --------------------------------------------------------------------------- the stub tracker

class StubTracker:
    """Stands in for solver.track.pipeline.track_sequence: returns the true poses (of the requested frame
    range) and per-frame rows; records what it was given."""

    def __init__(self, pkg, model, poses, adapted_model=None, notes=()):
        self.pipeline, self.model, self.poses = pkg("solver.track.pipeline"), model, poses
        self.adapted_model, self.notes, self.calls = adapted_model, list(notes), []

    def __call__(self, model, source, options, training_poses=None, progress=None, start_pose=None, resume=None):
        a, b = options.frames or (0, len(source))
        self.calls.append({"model": model, "points": [source[i].points for i in range(a, b)], "start": start_pose,
                           "resume": resume,
                           "training_poses": training_poses, "options": options,
                           "cameras": getattr(source, "cameras", None)})
        rows = [{"frame": a + j, "name": source.names[a + j], "mean_mm": 1.0 + j, "median_mm": 0.5 + j,
                 "mad_mm": 0.1, "iqr_mm": 0.2, "points": 10, "lost": False, "skipped": False, "reason": "",
                 "seconds": 0.0} for j in range(b - a)]
        part = Poses(self.poses.rotations[a:b], self.poses.translations[a:b], self.poses.scales[a:b])
        out = self.adapted_model or model
        return self.pipeline.TrackResult(part, out, self.adapted_model is not None, rows, [], [], {"pass 1": 0.0},
                                         "none", a, self.notes)


@pytest.fixture
def stub(pkg, monkeypatch, truth):
    def make(**kw):
        tracker = StubTracker(pkg, truth[0], truth[1], **kw)
        monkeypatch.setattr(pkg("addon.track.solve"), "track_sequence", tracker)
        return tracker
    return make


# --------------------------------------------------------------------------- building (stub)

def test_bundle_rig_stands_at_the_captures_matrix_and_plays_over_them(pkg, tmp_path, truth, stub):
    """stub: a bundle and a moved scan-sequence object: the solver gets the captures in their file
    coordinates, the rig built from the bundle gets the object's matrix, its evaluated mesh equals the
    true posed model placed there on every capture frame, and the residual curve is the rows' medians."""
    model, poses, captures = truth
    tracker = stub()
    ob = import_captures(tmp_path, captures, moved())
    path = str(tmp_path / "person.npz")
    save_bundle(path, model, poses)
    assert bpy.ops.articula.track(bundle=path, captures=ob.name, **FAST) == {'FINISHED'}
    (call,) = tracker.calls
    for k in range(N):
        np.testing.assert_allclose(call["points"][k], captures[k][0], atol=1e-6)     # file coordinates
    assert len(call["training_poses"]) == N
    arm = bpy.data.objects["person tracked"]
    np.testing.assert_allclose(np.array(arm.matrix_world), moved(), atol=1e-6)
    assert key_frames(pkg, arm) == {tuple(range(FRAME_START, FRAME_START + N))}
    mesh = pkg("addon.rig.reader").find_mesh(arm)
    posed = hybrid_skin(model, poses) @ moved()[:3, :3].T + moved()[:3, 3]
    for k in range(N):
        bpy.context.scene.frame_set(FRAME_START + k)
        np.testing.assert_allclose(evaluated_world(pkg, mesh), posed[k], atol=2e-5)
    frames = np.arange(FRAME_START, FRAME_START + N)
    np.testing.assert_allclose(fcurve_values(pkg, arm, "articula_residual_median_mm", frames), 0.5 + np.arange(N))
    np.testing.assert_allclose(fcurve_values(pkg, arm, "articula_residual_mean_mm", frames), 1.0 + np.arange(N))
    report = json.loads(arm["articula_track_report"])
    assert report["input"]["frames"] == N and report["model"]["training_poses"] == N
    assert report["options"]["prior"] == "none" and "frames" not in report["options"]


def test_error_colours_follow_the_frame(pkg, tmp_path, truth, stub):
    """stub: the capture mesh's error attribute is, at every frame, the distance (mm) of its points to the
    rig's evaluated mesh (about the 1 mm noise), its colours the heat map's; frames outside the tracked
    range show none; the values survive a frame change back."""
    model, poses, captures = truth
    stub()
    ob = import_captures(tmp_path, captures, moved())
    path = str(tmp_path / "person.npz")
    save_bundle(path, model, poses)
    assert bpy.ops.articula.track(bundle=path, captures=ob.name, use_frame_range=True, frame_first=FRAME_START + 1,
                                  frame_last=FRAME_START + 3, **FAST) == {'FINISHED'}
    arm = bpy.data.objects["person tracked"]
    assert key_frames(pkg, arm) == {tuple(range(FRAME_START + 1, FRAME_START + 4))}
    mesh = pkg("addon.rig.reader").find_mesh(arm)
    sd = pkg("solver.geometry.surface_distance")
    for k in (2, 1, 3, 2):
        bpy.context.scene.frame_set(FRAME_START + k)
        got = error_values(ob)
        want = 1000 * sd.distance_to_surface(world_points(ob), evaluated_world(pkg, mesh), model.faces)
        assert got is not None and len(got) == len(captures[k][0])
        np.testing.assert_allclose(got, want, atol=0.01)
        assert 0.3 < np.median(got) < 2.0
        assert ob.data.color_attributes.active_color_name == "articula_error_color"
    for outside in (0, 4):
        bpy.context.scene.frame_set(FRAME_START + outside)
        assert error_values(ob) is None
    assert ob.data["articula_error_scale_mm"] >= 1.0


def test_error_colours_travel_with_the_saved_blend(pkg, tmp_path, truth, stub, cache_home):
    """stub: tracked in an unsaved file, the error file lives in the cache folder's track_cache/; the first
    save moves it into ``<blend>_articula/`` (stored relative), Save As elsewhere copies it beside the new
    file (the first keeps its own), and a reopened copy shows the colours after its folder was moved."""
    model, poses, captures = truth
    stub()
    ob = import_captures(tmp_path, captures, moved())
    name = ob.name
    path = str(tmp_path / "person.npz")
    save_bundle(path, model, poses)
    assert bpy.ops.articula.track(bundle=path, captures=ob.name, **FAST) == {'FINISHED'}
    unsaved = bpy.path.abspath(ob["articula_track_errors"])
    assert os.path.dirname(unsaved) == str(cache_home / "track_cache") and os.path.isfile(unsaved)
    first = tmp_path / "a" / "take.blend"
    first.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(first))
    ob = bpy.data.objects[name]
    assert ob["articula_track_errors"].startswith("//take_articula/") and not os.path.exists(unsaved)
    in_first = bpy.path.abspath(ob["articula_track_errors"])
    assert os.path.isfile(in_first)
    second = tmp_path / "b" / "copy.blend"
    second.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(second))
    ob = bpy.data.objects[name]
    assert ob["articula_track_errors"].startswith("//copy_articula/") and os.path.isfile(in_first)
    moved_dir = tmp_path / "elsewhere"
    os.rename(second.parent, moved_dir)
    bpy.ops.wm.open_mainfile(filepath=str(moved_dir / "copy.blend"))
    ob = bpy.data.objects[name]
    bpy.context.scene.frame_set(FRAME_START + 2)
    got = error_values(ob)
    assert got is not None and len(got) == len(captures[2][0])


def test_adapted_model_gets_a_new_rig_and_hides_the_old(pkg, tmp_path, truth, stub):
    """stub: adaptation ran: a rig of the adapted model (same bones, its rest mesh) at the old rig's matrix
    plays the motion; the old rig is hidden and keeps its action."""
    model, poses, captures = truth
    adapted = synthetic.tube_body(rings=4, segments=6)
    adapted.rest_vertices[:] = model.rest_vertices + [0.0, 0.0, 0.01]
    stub(adapted_model=adapted)
    ob = import_captures(tmp_path, captures)
    old, _ = build_rig(tmp_path, model, poses)
    old.location = (0.5, 0, 0)
    old_action = old.animation_data.action
    select(old, ob)
    assert bpy.ops.articula.track(**FAST) == {'FINISHED'}
    new = bpy.data.objects["Person adapted"]
    assert old.hide_get() and not new.hide_get() and old.animation_data.action == old_action
    got = pkg("addon.rig.reader").read_model(new)
    np.testing.assert_allclose(got.rest_vertices, adapted.rest_vertices, atol=1e-6)
    np.testing.assert_allclose(np.array(new.matrix_world), np.array(old.matrix_world), atol=1e-7)
    assert key_frames(pkg, new) == {tuple(range(FRAME_START, FRAME_START + N))}


def test_tracking_again_trains_on_the_same_action(pkg, tmp_path, truth, stub):
    """stub: the rig's first track replaces its (training) action; tracking again still learns from the
    training poses, not from the tracked motion."""
    model, poses, captures = truth
    tracker = stub()
    ob = import_captures(tmp_path, captures)
    rig, _ = build_rig(tmp_path, model, Poses(poses.rotations[:3], poses.translations[:3], poses.scales[:3]))
    training = rig.animation_data.action
    for _ in range(2):
        select(rig, ob)
        assert bpy.ops.articula.track(**FAST) == {'FINISHED'}
    assert [len(c["training_poses"]) for c in tracker.calls] == [3, 3]
    assert rig.animation_data.action != training and training.use_fake_user
    assert rig["articula_training_action"] == training.name


def test_start_from_the_rigs_current_pose(pkg, tmp_path, truth, stub):
    """stub: with Start From Rig's Pose the tracker gets the pose the rig holds now (its action's value at
    the current frame, with an unkeyed edit of one bone on top) in the solve frame; without it, none; the
    report says how the first frame started."""
    model, poses, captures = truth
    tracker = stub()
    ob = import_captures(tmp_path, captures)
    rig, _ = build_rig(tmp_path, model, poses)
    bpy.context.scene.frame_set(3)                                   # the action's third key: poses[2]
    edited = rig.pose.bones[rig.data.bones[1].name]
    edited.rotation_quaternion = (0.9, 0.1, 0.3, -0.2)
    select(rig, ob)
    assert bpy.ops.articula.track(start_from_rig=True, **FAST) == {'FINISHED'}
    assert json.loads(rig["articula_track_report"])["input"]["start"] == "the rig's pose"
    assert bpy.ops.articula.track(**FAST) == {'FINISHED'}
    assert json.loads(rig["articula_track_report"])["input"]["start"] == "automatic"
    start, none = tracker.calls[0]["start"], tracker.calls[1]["start"]
    assert none is None and len(start) == 1
    names = pkg("addon.rig.reader").control_names(rig)
    want = poses.rotations[2].copy()
    b = names.index(edited.name)
    want[b] = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
    np.testing.assert_allclose(start.rotations[0], want, atol=1e-6)
    np.testing.assert_allclose(start.translations[0], poses.translations[2], atol=1e-6)


# --------------------------------------------------------------------------- the real tracker

def test_track_a_moved_scan_sequence_with_a_rig(pkg, tmp_path, truth):
    """The real pipeline: a rig at the origin, the captures moved and turned in the scene: the tracked rig's
    evaluated mesh lies on the captures in world coordinates (median distance near the noise), the bundle
    holds one pose per frame in the solve frame (here the world), the report's medians are the curve's."""
    model, poses, captures = truth
    ob = import_captures(tmp_path, captures, moved())
    rig, _ = build_rig(tmp_path, model)
    select(rig, ob)
    out = str(tmp_path / "tracked.npz")
    assert bpy.ops.articula.track(output_bundle=out, **FAST) == {'FINISHED'}
    bundle = pkg("solver.formats.bundle").load_bundle(out)
    assert len(bundle.poses) == N and bundle.provenance["source"] == "track"
    assert bundle.provenance["first_frame"] == 0 and bundle.provenance["input"]["frames"] == N
    mesh = pkg("addon.rig.reader").find_mesh(rig)
    posed = hybrid_skin(bundle.model, bundle.poses)
    sd = pkg("solver.geometry.surface_distance")
    report = json.loads(rig["articula_track_report"])
    for k in range(N):
        bpy.context.scene.frame_set(FRAME_START + k)
        np.testing.assert_allclose(evaluated_world(pkg, mesh), posed[k], atol=5e-5)
        d = 1000 * sd.distance_to_surface(world_points(ob), posed[k], model.faces)
        assert np.median(d) < 3.0, k
        np.testing.assert_allclose(error_values(ob), d, atol=0.05)
    medians = [r["median_mm"] for r in report["frames"]]
    np.testing.assert_allclose(fcurve_values(pkg, rig, "articula_residual_median_mm",
                                             np.arange(FRAME_START, FRAME_START + N)), medians, rtol=1e-5)


def test_cancel_leaves_scene_unchanged(pkg, tmp_path, truth, monkeypatch):
    """Esc while frame 2 is tracked creates nothing and changes no action."""
    jobs = pkg("addon.jobs")
    model, poses, captures = truth
    ob = import_captures(tmp_path, captures)
    rig, _ = build_rig(tmp_path, model, poses)
    select(rig, ob)
    seen = []

    class CancelAtFrameTwo(jobs.Progress):
        def __call__(self, fraction, text=""):
            seen.append(text)
            if "frame 2 of" in text:
                self.cancel()
            super().__call__(fraction, text)

    monkeypatch.setattr(jobs, "Progress", CancelAtFrameTwo)
    before = scene_state()
    assert bpy.ops.articula.track(**FAST) == {'CANCELLED'}
    assert scene_state() == before and "articula_track_errors" not in ob
    assert any("frame 1 of 5" in t and "mm" in t for t in seen) and "done" not in seen


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("case, message", [
    ("no_rig", "no rig: make an Articula rig active"),
    ("no_captures", "no captures: select a scan-sequence or point-cloud object"),
    ("two_captures", "several capture objects are selected"),
    ("not_captures", "'Cube' is not a scan-sequence or point-cloud object"),
    ("missing_bundle", "nowhere.npz: no such bundle file"),
    ("range", r"Frame Range 1..4 lies outside the captures' frames 3..7"),
    ("out_folder", "does not exist"),
    ("start_with_bundle", "Start From Rig's Pose needs a rig in the scene"),
    ("units", "captures and model differ in size.*centimetres"),
])
def test_bad_input_is_refused_and_leaves_scene_unchanged(pkg, tmp_path, truth, case, message):
    model, poses, captures = truth
    ob = import_captures(tmp_path, captures)
    rig, _ = build_rig(tmp_path, model, poses)
    kwargs = dict(FAST)
    select(rig, ob)
    if case == "no_rig":
        select(ob)
    elif case == "no_captures":
        select(rig)
    elif case == "two_captures":
        other = import_captures(tmp_path, captures[:2], name="more")
        select(rig, ob, other)
    elif case == "not_captures":
        bpy.ops.mesh.primitive_cube_add()
        bpy.context.active_object.name = "Cube"
        select(rig)
        kwargs["captures"] = "Cube"
    elif case == "missing_bundle":
        kwargs["bundle"] = str(tmp_path / "nowhere.npz")
    elif case == "range":
        kwargs.update(use_frame_range=True, frame_first=1, frame_last=4)
    elif case == "out_folder":
        kwargs["output_bundle"] = str(tmp_path / "no" / "such" / "t.npz")
    elif case == "start_with_bundle":
        kwargs.update(bundle=str(tmp_path / "Person.npz"), start_from_rig=True)
    elif case == "units":
        ob.scale = (100, 100, 100)          # the captures are in centimetres as the scene shows them
    before = scene_state()
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.articula.track(**kwargs)
    assert scene_state() == before


def test_point_cloud_object_is_tracked_in_world_coordinates(pkg, tmp_path, truth, stub):
    """stub: a point-cloud object (points in its sensor frame, placed by world_from_sensor) given to the
    capture tracker (Tracker: Captures; Auto takes the depth tracker for a cloud with a camera): with a
    bundle the solver gets the points in world coordinates and the cameras of the recording, the rig stands
    at the origin, and the point cloud gets its error colours."""
    from types import SimpleNamespace
    model, poses, captures = truth
    tracker = stub()
    sensor_to_world = moved()
    to_sensor = np.linalg.inv(sensor_to_world)
    frames = [SimpleNamespace(points=(p @ to_sensor[:3, :3].T + to_sensor[:3, 3]).astype(np.float32), normals=None,
                              colors=None) for p, _ in captures]
    seq = pkg("solver.formats.point_files").PointSequence.from_frames(
        frames, world_from_sensor=sensor_to_world, intrinsics=(320, 240, 300.0, 300.0, 159.5, 119.5),
        frame_names=[f"p{k}.ply" for k in range(N)])
    cache = str(tmp_path / "cloud-0123abcd.points.npz")
    seq.save(cache)
    points = pkg("addon.sequences.points")
    ob, cam = points.create_sequence_objects(bpy.context, "cloud", seq, cache, "test", frame_start=FRAME_START)
    path = str(tmp_path / "person.npz")
    save_bundle(path, model, poses)
    assert bpy.ops.articula.track(bundle=path, captures=ob.name, method='CAPTURES', **FAST) == {'FINISHED'}
    (call,) = tracker.calls
    for k in range(N):
        np.testing.assert_allclose(call["points"][k], captures[k][0], atol=1e-5)        # world coordinates
    (cam_to_world, intr), = call["cameras"][0]
    np.testing.assert_allclose(cam_to_world, sensor_to_world, atol=1e-5)
    assert (intr.width, intr.fx) == (320, 300.0)
    arm = bpy.data.objects["person tracked"]
    np.testing.assert_allclose(np.array(arm.matrix_world), np.eye(4), atol=1e-7)
    bpy.context.scene.frame_set(FRAME_START + 2)
    got = error_values(ob)
    mesh = pkg("addon.rig.reader").find_mesh(arm)
    want = 1000 * pkg("solver.geometry.surface_distance").distance_to_surface(
        world_points(ob), evaluated_world(pkg, mesh), model.faces)
    np.testing.assert_allclose(got, want, atol=0.01)


def test_action_names_say_rig_and_recording_once(pkg, tmp_path, truth):
    """The real pipeline, tracking again and again on the same rig (from the bundle, then the rig it
    built, after a bake onto it): every tracked action is "<model> tracked <recording>" (Blender's .001
    for repeats), never "tracked tracked"; adapting an adapted rig names it "<rig> adapted" once."""
    model, poses, captures = truth
    ob = import_captures(tmp_path, captures, name="walk")
    path = str(tmp_path / "person.npz")
    save_bundle(path, model, Poses(poses.rotations[:3], poses.translations[:3], poses.scales[:3]))
    assert bpy.ops.articula.track(bundle=path, captures=ob.name, **FAST) == {'FINISHED'}
    rig = bpy.data.objects["person tracked"]
    select(rig, ob)
    assert bpy.ops.articula.track(**FAST) == {'FINISHED'}
    assert bpy.ops.articula.bake_poses(filepath=path, armature=rig.name) == {'FINISHED'}
    select(rig, ob)
    assert bpy.ops.articula.track(**FAST) == {'FINISHED'}
    tracked = sorted(a.name for a in bpy.data.actions if a.get("articula_tracked"))
    assert len(tracked) == 3 and rig.animation_data.action.name in tracked, tracked
    assert all(re.fullmatch(r"person tracked walk(\.\d{3})?", n) for n in tracked), tracked
    assert not [a.name for a in bpy.data.actions if "tracked tracked" in a.name or "poses poses" in a.name]
    actions = pkg("addon.rig.actions")
    assert actions.adapted_rig_name("Person adapted.001") == actions.adapted_rig_name("Person") == "Person adapted"
    assert actions.tracked_action_name("learned tracked", os.path.join("out", "data", "unreg")) \
        == "learned tracked unreg"
