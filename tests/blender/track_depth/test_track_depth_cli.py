"""The batch command ``track --depth``: the tracked bundle holds the poses of the solver run on the same
folder (same numbers) with the model's bone names, in the world of intrinsics.json's cam_to_world (or,
for a folder without intrinsics.json tracked with ``--camera kinect_v1``, in the camera frame); the
.blend has the imported recording with the rig standing over its points, seen through its camera; the
real Kinect frames are tracked with the template; bad input fails with one line naming the problem and
writes nothing.

Data: the tiny synthetic recording of test_track_depth.py (160x120, 4 frames) and, for the Kinect preset,
its frames copied without intrinsics.json.
"""
import json
import os
import shutil

import bpy
import numpy as np
import pytest

from articula.sample_scenes.depth_bench import bench_recording
from articula.solver.formats.bundle import load_bundle
from articula.solver.formats.png16 import write_png16
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.track_depth.options import DepthTrackOptions
from articula.solver.track_depth.pipeline import track_recording
from articula.solver.track_depth.source import DepthRecording
from ...conftest import SHARED_DATA

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

N = 4
KINECT = os.path.join(SHARED_DATA, "depth", "skeltrack_kinect")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    return bench_recording(tmp_path_factory.mktemp("depth") / "rec", subject_seed=0, resolution=(160, 120), frames=N)


def joints(model, poses, bench):
    """Heads (N, 14, 3) of the major joints' bones of ``model`` posed by ``poses`` (the model's frame)."""
    Rm, tm = forward_kinematics(model.skeleton, poses)
    heads = np.einsum("nbij,bj->nbi", Rm, model.skeleton.heads) + tm
    names = [bench["model"].skeleton.names[b] for b in bench["joint_bones"]]
    return heads[:, [model.skeleton.names.index(n) for n in names]]


def apply(m, p):
    return p @ m[:3, :3].T + m[:3, 3]


def world_points(ob):
    me = ob.data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    return apply(np.array(ob.matrix_world), co.reshape(-1, 3))


def test_track_depth_writes_the_solvers_poses_in_the_world_and_a_blend(pkg, bench, tmp_path):
    folder, model_path = bench["out_dir"], bench["model_path"]
    out, rep, blend = (str(tmp_path / n) for n in ("t.npz", "t.json", "t.blend"))
    assert pkg("addon.cli.main").main(["track", "--depth", folder, "--model", model_path, "--frames", "1:4",
                                       "--out", out, "--report", rep, "--blend", blend]) == 0
    bundle = load_bundle(out)
    model = bench["model"]
    assert list(bundle.model.skeleton.names) == list(model.skeleton.names) and len(bundle.poses) == 3
    direct = track_recording(DepthRecording.from_folder(folder, frames=slice(1, 4)), model)
    np.testing.assert_array_equal(bundle.poses.rotations, direct.poses.rotations)        # same numbers
    np.testing.assert_array_equal(bundle.poses.translations, direct.poses.translations)
    err = np.linalg.norm(joints(bundle.model, bundle.poses, bench) - bench["joints"][1:], axis=-1)
    assert np.median(err) < 0.04, np.round(100 * err, 1)                  # intrinsics.json's world frame
    prov = bundle.provenance
    assert prov["first_frame"] == 1 and prov["frame_names"] == [f"depth_{k:04d}.png" for k in (1, 2, 3)]
    assert prov["coordinates"].startswith("world") and prov["tracker"] == f"depth {DepthTrackOptions().tracker}"
    doc = json.load(open(rep))
    assert doc["input"]["first_frame"] == 1 and len(doc["per_frame"]) == 3 and doc["template"] is False
    # the .blend: the recording imported in the floor's world, the rig standing over its points
    bpy.ops.wm.open_mainfile(filepath=blend)
    ob = next(o for o in bpy.data.objects if o.articula.kind == 'POINT_CLOUD_SEQUENCE')
    arm = next(o for o in bpy.data.objects if o.articula.kind == 'RIG_ARMATURE')
    assert bpy.context.scene.camera == ob.parent
    assert tuple(arm.animation_data.action.frame_range) == (2, 4)
    to_blender = np.array(ob.matrix_world) @ np.linalg.inv(bench["cam_to_world"])
    np.testing.assert_allclose(np.array(arm.matrix_world), to_blender, atol=1e-5)
    mesh = pkg("addon.rig.reader").find_mesh(arm)
    names = [model.skeleton.names[b] for b in bench["joint_bones"]]
    from scipy.spatial import cKDTree
    for k in (1, 2, 3):
        bpy.context.scene.frame_set(1 + k)
        m = np.array(arm.matrix_world)
        shown = apply(m, np.array([tuple(arm.pose.bones[n].head) for n in names]))
        assert np.median(np.linalg.norm(shown - apply(to_blender, bench["joints"][k]), axis=-1)) < 0.04, k
        body = apply(np.array(mesh.matrix_world), pkg("addon.scene.mesh_io").evaluated_positions(mesh))
        near, _ = cKDTree(body).query(world_points(ob))
        assert np.median(near) < 0.02, (k, np.median(near))             # the points lie on the rig's body


def test_kinect_preset_folder_is_tracked_in_the_camera_frame(pkg, bench, tmp_path, capsys):
    """The frames without intrinsics.json: refused without --camera; with --camera kinect_v1 (the bench's
    camera) the poses are in the camera frame (OpenCV axes); in the .blend (imported with the Kinect v1
    preset) the rig stands at the depth object's matrix, its body on the points."""
    folder = tmp_path / "kinect"
    folder.mkdir()
    for p in bench["depth_paths"]:
        shutil.copy(p, folder)
    cli = pkg("addon.cli.main")
    out = str(tmp_path / "t.npz")
    assert cli.main(["track", "--depth", str(folder), "--out", out]) == 2
    assert "kinect: no intrinsics.json; give the camera with --camera (kinect_v1" in capsys.readouterr().err
    assert not os.path.exists(out)
    blend = str(tmp_path / "k.blend")
    assert cli.main(["track", "--depth", str(folder), "--camera", "kinect_v1", "--model", bench["model_path"],
                     "--out", out, "--blend", blend]) == 0
    printed = capsys.readouterr().out
    assert "no intrinsics.json: the kinect_v1 camera preset is assumed" in printed
    bundle = load_bundle(out)
    in_camera = apply(np.linalg.inv(bench["cam_to_world"]), bench["joints"])
    err = np.linalg.norm(joints(bundle.model, bundle.poses, bench) - in_camera, axis=-1)
    assert np.median(err) < 0.04, np.round(100 * err, 1)
    assert bundle.provenance["coordinates"].startswith("camera")
    bpy.ops.wm.open_mainfile(filepath=blend)
    ob = next(o for o in bpy.data.objects if o.articula.kind == 'POINT_CLOUD_SEQUENCE')
    arm = next(o for o in bpy.data.objects if o.articula.kind == 'RIG_ARMATURE')
    np.testing.assert_allclose(np.array(arm.matrix_world), np.array(ob.matrix_world), atol=1e-6)
    mesh = pkg("addon.rig.reader").find_mesh(arm)
    from scipy.spatial import cKDTree
    bpy.context.scene.frame_set(2)
    body = apply(np.array(mesh.matrix_world), pkg("addon.scene.mesh_io").evaluated_positions(mesh))
    assert np.median(cKDTree(body).query(world_points(ob))[0]) < 0.02


def test_real_kinect_frames_are_tracked_with_the_template(pkg, tmp_path, capsys):
    """Two frames of the real Kinect v1 recording (no intrinsics.json) with the template body: a pose per
    frame with the template's bones, the person in front of the camera (camera frame, +Z forward)."""
    out, rep = str(tmp_path / "k.npz"), str(tmp_path / "k.json")
    assert pkg("addon.cli.main").main(["track", "--depth", KINECT, "--camera", "KINECT_V1", "--frames", "0:2",
                                       "--out", out, "--report", rep]) == 0
    bundle = load_bundle(out)
    template = pkg("solver.track_depth.template").load_template().base
    assert list(bundle.model.skeleton.names) == list(template.skeleton.names) and len(bundle.poses) == 2
    doc = json.load(open(rep))
    assert doc["template"] is True and [f["status"] for f in doc["per_frame"]][0] == "initialised"
    Rm, tm = forward_kinematics(bundle.model.skeleton, bundle.poses)
    hips = np.einsum("nij,j->ni", Rm[:, 0], bundle.model.skeleton.heads[0]) + tm[:, 0]
    assert np.all((hips[:, 2] > 0.8) & (hips[:, 2] < 4.5)), hips               # metres in front of the camera
    assert "model: the built-in template body" in capsys.readouterr().out
    assert doc["per_frame"][0]["others"] == 1 and doc["others_in_view"] == [0]
    right = str(tmp_path / "r.npz")               # the other person of frame 0, chosen by --person
    assert pkg("addon.cli.main").main(["track", "--depth", KINECT, "--camera", "KINECT_V1", "--frames", "0:1",
                                       "--person", "right", "--out", right]) == 0
    other = load_bundle(right)
    Ro, to = forward_kinematics(other.model.skeleton, other.poses)
    hips_right = Ro[0, 0] @ other.model.skeleton.heads[0] + to[0, 0]
    assert hips_right[0] > hips[0, 0] + 0.3, (hips_right, hips[0])       # camera +X is the image's right


def test_bad_input_fails_and_writes_nothing(pkg, bench, tmp_path, capsys):
    cli = pkg("addon.cli.main")
    out, rep = str(tmp_path / "t.npz"), str(tmp_path / "t.json")
    eight = tmp_path / "eight"
    shutil.copytree(bench["out_dir"], eight)
    write_png16(str(eight / "depth_0002.png"), np.zeros((120, 160), np.uint8))
    absurd = tmp_path / "absurd"
    shutil.copytree(bench["out_dir"], absurd)
    intr = json.load(open(absurd / "intrinsics.json"))
    intr["fx"] = 5.0
    json.dump(intr, open(absurd / "intrinsics.json", "w"))
    empty = tmp_path / "empty"
    empty.mkdir()
    folder = bench["out_dir"]
    cases = [
        (["--depth", str(tmp_path / "nowhere")], "nowhere: not a folder"),
        (["--depth", str(empty)], "empty: no frames found"),
        (["--depth", str(eight)], "depth_0002.png: 8-bit PNG"),
        (["--depth", str(absurd)], "intrinsics.json: fx = 5 px gives a horizontal field of view"),
        (["--depth", folder, "--scans", folder], "--depth and --scans exclude each other"),
        ([], "nothing to track: give --scans PATH... (captures) or --depth DIR"),
        (["--scans", folder], "--scans needs --model MODEL.npz"),
        (["--scans", folder, "--model", bench["model_path"], "--tracker", "gmm"], "--tracker: for --depth only"),
        (["--depth", folder, "--start-pose", bench["model_path"]], "--start-pose: for --scans only"),
        (["--depth", folder, "--frames", "2:9"], "--frames 2:9: the input has 4 frames"),
        (["--depth", folder, "--model", str(tmp_path / "none.npz")], "none.npz: no such bundle file"),
        (["--depth", folder, "--report", str(tmp_path / "no" / "r.json")], "does not exist"),
    ]
    for args, message in cases:
        assert cli.main(["track", *args, "--out", out, "--report", rep] if "--report" not in args
                        else ["track", *args, "--out", out]) == 2, args
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, (args, err)
        assert not os.path.exists(out) and not os.path.exists(rep), args


def test_tracker_flag_reaches_the_solver(pkg, bench, tmp_path, solver_options):
    """``--tracker gmm`` and ``--person`` are the depth tracker's options (the run itself is the solver's to
    test)."""
    out = str(tmp_path / "t.npz")
    assert pkg("addon.cli.main").main(["track", "--depth", bench["out_dir"], "--tracker", "GMM", "--person", "left",
                                       "--out", out]) == 3
    assert [(o.tracker, o.person) for o in solver_options] == [("gmm", "left")] and not os.path.exists(out)
