"""A whole depth recording tracked (solver.track_depth.pipeline): a short synthetic turning recording
with the subject's exact model and with the template, frames with nobody in view, numbering gaps,
refused inputs, and the same frames tracked from an imported point sequence."""
import json
import os
import shutil

import numpy as np
import pytest

from articula.solver.depth import camera as cam
from articula.solver.depth import frames as dp
from articula.solver.depth import recording as rec
from articula.solver.errors import ArticulaInputError
from articula.solver.formats.png16 import read_png16, write_png16
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.track_depth.options import DepthTrackOptions
from articula.solver.track_depth.pipeline import track_recording
from articula.solver.track_depth.smoothing import runs, smooth
from articula.solver.track_depth.source import DepthRecording, PointsRecording, numbering_gaps

FRAMES = 10


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from articula.sample_scenes.depth_bench import bench_recording
    return bench_recording(str(tmp_path_factory.mktemp("depth") / "rec"), 1, (320, 240), FRAMES)


def _joints(model, poses, bones):
    Rm, tm = forward_kinematics(model.skeleton, poses)
    return (np.einsum("nbij,bj->nbi", Rm, model.skeleton.heads) + tm)[:, bones]


def _copy(src, dst):
    shutil.copytree(src, dst)
    return dst


def test_exact_model_tracks_the_major_joints(recording):
    res = track_recording(DepthRecording.from_folder(recording["out_dir"]), recording["model"])
    e = np.linalg.norm(_joints(res.model, res.poses, recording["joint_bones"]) - recording["joints"], axis=2)
    rep = res.report()
    assert len(res.poses) == FRAMES and rep["lost"] == 0 and rep["no_person"] == 0
    assert e.mean() < 0.035 and np.median(e) < 0.03
    assert res.frames[0]["status"] == "initialised" and json.dumps(rep)
    assert res.model is recording["model"] and not res.template


def test_template_adapts_and_keeps_its_names(recording):
    res = track_recording(DepthRecording.from_folder(recording["out_dir"]), None,
                          DepthTrackOptions(size_frames=3, surface_every=3))
    from articula.solver.track_depth.template import load_template
    base = load_template().base
    assert res.template and res.model.skeleton.names == base.skeleton.names
    assert res.model.num_vertices == base.num_vertices and not np.allclose(res.model.rest_vertices, base.rest_vertices)
    names = res.model.skeleton.names
    bones = [names.index(recording["model"].skeleton.names[b]) for b in recording["joint_bones"]]
    e = np.linalg.norm(_joints(res.model, res.poses, bones) - recording["joints"], axis=2)
    assert np.median(e) < 0.06


def _rotation(axis, degrees):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(degrees)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


@pytest.mark.parametrize("world", ["yup", "tilt30", "camera"])
def test_any_world_orientation_tracks_as_z_up(recording, tmp_path, world):
    """The same frames with intrinsics.json's world Y-up, tilted 30 deg (origin moved) or absent (camera
    frame): the joints, in that world, are as near the truth as in the generated Z-up world."""
    c2w = recording["cam_to_world"]
    G = np.eye(4)
    if world == "camera":
        G = np.linalg.inv(c2w)
    else:
        G[:3, :3] = _rotation([1, 0, 0], -90.0) if world == "yup" else _rotation([1, 1, 0], 30.0)
        G[:3, 3] = (0.4, -0.7, 0.25)
    folder = tmp_path / world
    folder.mkdir()
    for p in recording["depth_paths"]:
        shutil.copy(p, folder)
    cam.save_intrinsics(folder / "intrinsics.json", cam.load_intrinsics(recording["intrinsics"]),
                        cam_to_world=None if world == "camera" else G @ c2w)
    truth = recording["joints"] @ G[:3, :3].T + G[:3, 3]
    res = track_recording(DepthRecording.from_folder(str(folder)), recording["model"])
    e = np.linalg.norm(_joints(res.model, res.poses, recording["joint_bones"]) - truth, axis=2)
    rep = res.report()
    assert rep["lost"] == 0 and e.mean() < 0.035, (world, e.mean(), rep["statuses"])


def test_nobody_in_view_is_reported_and_tracking_resumes(recording, tmp_path):
    folder = _copy(recording["out_dir"], str(tmp_path / "gap"))
    paths = rec.list_frames(folder, (".png",))
    for k in (4, 5):
        z = read_png16(paths[k])
        z[: int(0.75 * z.shape[0])] = 0               # only the floor is left
        write_png16(paths[k], z)
    res = track_recording(DepthRecording.from_folder(folder), recording["model"])
    status = [f["status"] for f in res.frames]
    assert status[4] == status[5] == "no person" and status[6] == "initialised"
    e = np.linalg.norm(_joints(res.model, res.poses, recording["joint_bones"]) - recording["joints"], axis=2)
    assert e[6:].mean() < 0.04


def test_missing_numbers_are_noted(recording, tmp_path):
    folder = _copy(recording["out_dir"], str(tmp_path / "holes"))
    os.remove(os.path.join(folder, "depth_0003.png"))
    r = DepthRecording.from_folder(folder)
    assert len(r) == FRAMES - 1 and any("depth_0002.png and depth_0004.png" in n for n in r.notes)
    assert numbering_gaps(["a_1.png", "a_2.png", "a_5.png"]) == [("a_2.png", "a_5.png")]


def test_bad_inputs_are_refused_early(recording, tmp_path):
    folder = _copy(recording["out_dir"], str(tmp_path / "bad"))
    ipath = os.path.join(folder, "intrinsics.json")
    data = json.load(open(ipath))
    json.dump(dict(data, fx=5.0, fy=5.0), open(ipath, "w"))
    with pytest.raises(ArticulaInputError, match="field of view"):
        DepthRecording.from_folder(folder)
    os.remove(ipath)
    with pytest.raises(ArticulaInputError, match="no intrinsics.json"):
        DepthRecording.from_folder(folder)
    assert DepthRecording.from_folder(folder, preset="kinect_v1").notes[0].startswith("no intrinsics.json")
    write_png16(os.path.join(folder, "depth_0002.png"), np.full((240, 320), 100, np.uint8))   # 8-bit PNG
    with pytest.raises(ArticulaInputError, match="8-bit"):
        DepthRecording.from_folder(folder, preset="kinect_v1")
    with pytest.raises(ArticulaInputError, match="not a folder"):
        DepthRecording.from_folder(str(tmp_path / "nowhere"))
    with pytest.raises(ArticulaInputError, match="tracker"):
        DepthTrackOptions(tracker="magic").validate()


def test_imported_points_track_like_the_frames(recording):
    folder = recording["out_dir"]
    ipath = os.path.join(folder, "intrinsics.json")
    seq = rec.import_depth(rec.png_frames(rec.list_frames(folder, (".png",))), cam.load_intrinsics(ipath),
                           dp.DepthOptions())
    a = track_recording(PointsRecording(seq, cam.load_camera_pose(ipath)), recording["model"])
    b = track_recording(DepthRecording.from_folder(folder), recording["model"])
    ja = _joints(a.model, a.poses, recording["joint_bones"])
    jb = _joints(b.model, b.poses, recording["joint_bones"])
    assert np.median(np.linalg.norm(ja - jb, axis=2)) < 0.02


def test_smoothing_runs_and_effect():
    assert runs(["initialised", "tracked", "tracked", "no person", "initialised", "tracked"]) == [(0, 3), (4, 6)]
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    rng = np.random.default_rng(0)
    angle = np.linspace(0, 1, 20)[:, None] + rng.normal(0, 0.05, (20, 1))
    rot = rotvec_to_quat(np.concatenate([angle, np.zeros((20, 2))], axis=1))[:, None]
    p = Poses(rot, np.zeros((20, 3)), np.ones(20))
    s = smooth(p, ["initialised"] + ["tracked"] * 19)
    from articula.solver.geometry.rotations import quat_to_rotvec
    before = np.abs(np.diff(quat_to_rotvec(p.rotations[:, 0])[:, 0], 2)).mean()
    after = np.abs(np.diff(quat_to_rotvec(s.rotations[:, 0])[:, 0], 2)).mean()
    assert after < 0.6 * before and np.allclose(s.rotations[0], p.rotations[0])
    jump = np.zeros((5, 3))
    jump[2, 0] = np.radians(60.0)        # one frame a different pose: kept as fitted, the others smoothed
    q = Poses(rotvec_to_quat(jump)[:, None], np.zeros((5, 3)), np.ones(5))
    out = smooth(q, ["initialised"] + ["tracked"] * 4)
    assert np.allclose(out.rotations, q.rotations)
    moved = Poses(p.rotations[:5].copy(), np.array([[0, 0, 0], [0, 0, 0], [0.3, 0, 0], [0, 0, 0], [0, 0, 0.0]]),
                  np.ones(5))
    assert np.allclose(smooth(moved, ["initialised"] + ["tracked"] * 4).translations[2], [0.3, 0, 0])
