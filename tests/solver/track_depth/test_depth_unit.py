"""The depth tracker reads 16-bit PNG frames in the camera's ``depth_unit_m`` (intrinsics.json), as the
importer does: a recording stored in 0.5 mm units is tracked where the person stands, against the
renderer's ground truth."""
import json
import os
import shutil

import numpy as np
import pytest

from articula.solver.depth import camera as cam
from articula.solver.depth import frames as dp
from articula.solver.depth import recording as rec
from articula.solver.formats.png16 import read_png16, write_png16
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.track_depth.pipeline import track_recording
from articula.solver.track_depth.source import DepthRecording

FRAMES = 2


@pytest.fixture(scope="module")
def half_mm(tmp_path_factory):
    """A bench recording (millimetre PNGs) rewritten in 0.5 mm units, with its ground truth."""
    from articula.sample_scenes.depth_bench import bench_recording
    recording = bench_recording(str(tmp_path_factory.mktemp("depth") / "rec"), 1, (320, 240), FRAMES)
    folder = str(tmp_path_factory.mktemp("half") / "rec")
    shutil.copytree(recording["out_dir"], folder)
    for path in rec.list_frames(folder, (".png",)):
        mm = read_png16(path).astype(np.int64)
        assert mm.max() * 2 < 65536
        write_png16(path, (2 * mm).astype(np.uint16))
    ipath = os.path.join(folder, "intrinsics.json")
    data = json.load(open(ipath))
    json.dump(dict(data, depth_unit_m=0.0005), open(ipath, "w"))
    return recording, folder


def test_half_millimetre_units_track_where_the_person_stands(half_mm):
    recording, folder = half_mm
    res = track_recording(DepthRecording.from_folder(folder), recording["model"])
    Rm, tm = forward_kinematics(res.model.skeleton, res.poses)
    joints = (np.einsum("nbij,bj->nbi", Rm, res.model.skeleton.heads) + tm)[:, recording["joint_bones"]]
    err = np.linalg.norm(joints - recording["joints"], axis=2)
    centre = cam.load_camera_pose(os.path.join(folder, "intrinsics.json"))[:3, 3]
    distance = np.linalg.norm(joints.mean(axis=1) - centre, axis=1)
    truth = np.linalg.norm(recording["joints"].mean(axis=1) - centre, axis=1)
    print(f"distance {distance} m, truth {truth} m, joint error median {np.median(err):.3f} m")
    np.testing.assert_allclose(distance, truth, atol=0.03)
    assert np.median(err) < 0.04


def test_importer_and_tracker_read_the_same_metres(half_mm):
    """One frame decoded by the importer's options and by the tracker's: the same depth in metres as the
    millimetre original."""
    recording, folder = half_mm
    intr, _ = rec.camera_file(os.path.join(folder, "intrinsics.json"))
    imported = rec.unit_options(dp.DepthOptions(), intr)
    tracked = DepthRecording.from_folder(folder).options
    original = read_png16(recording["depth_paths"][0]) * 0.001
    frame = rec.png_frames(rec.list_frames(folder, (".png",))[:1])
    for opts in (imported, tracked):
        (_, z), = rec.stream_metres(frame, opts, original.shape)
        ok = np.isfinite(z)
        assert ok.sum() > 1000
        np.testing.assert_allclose(z[ok], original[ok], atol=1e-6)
    explicit = DepthRecording.from_folder(folder, depth_scale=0.001).options
    assert explicit.depth_scale == 0.001
