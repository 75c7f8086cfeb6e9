"""EXR depth frames (metres, read by Blender) on the depth tracker's own reading path (``track --depth``:
``addon.track_depth.inputs.recording_from_folder`` -> ``DepthRecording``): the same recording written as
16-bit PNG (millimetres) and as EXR gives the tracker the same floor, the same person and the same tracked
poses, against the renderer's ground truth.

Data: a tiny synthetic recording (160x120, 3 frames; sample_scenes.depth_bench)."""
import os
import shutil

import bpy
import numpy as np
import pytest

from articula.sample_scenes.depth_bench import bench_recording
from articula.solver.depth import recording as rec
from articula.solver.formats.png16 import read_png16
from articula.solver.rig.kinematics import forward_kinematics

pytestmark = pytest.mark.usefixtures("cache_home")
N = 3


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """(bench recording, its PNG folder, the same frames as EXR metres with the same intrinsics.json)."""
    bench = bench_recording(tmp_path_factory.mktemp("depth") / "rec", subject_seed=0, resolution=(160, 120),
                            frames=N)
    exr = str(tmp_path_factory.mktemp("exr") / "rec")
    os.makedirs(exr)
    shutil.copy(bench["intrinsics"], exr)
    for path in rec.list_frames(bench["out_dir"], (".png",)):
        metres = read_png16(path).astype(np.float32) / 1000
        h, w = metres.shape
        img = bpy.data.images.new("d", w, h, float_buffer=True)
        img.colorspace_settings.is_data = True
        px = np.zeros((h, w, 4), np.float32)
        px[..., 0] = metres[::-1]                           # Blender rows run bottom to top
        px[..., 3] = 1
        img.pixels.foreach_set(px.ravel())
        img.filepath_raw = os.path.join(exr, os.path.basename(path)[:-4] + ".exr")
        img.file_format = 'OPEN_EXR'
        img.save()
        bpy.data.images.remove(img)
    return bench, bench["out_dir"], exr


def test_exr_frames_are_observed_like_png_frames(pkg, folders):
    _, png, exr = folders
    inputs = pkg("addon.track_depth.inputs")
    a, b = (inputs.recording_from_folder(f).recording for f in (png, exr))
    assert all(p.endswith(".exr") for p in b.paths) and len(b) == len(a) == N
    a.prepare()
    b.prepare()
    np.testing.assert_allclose(b.setup.floor[0], a.setup.floor[0], atol=1e-6)
    assert abs(b.setup.floor[1] - a.setup.floor[1]) < 1e-5
    for (ka, oa), (kb, ob) in zip(a.observations(2500), b.observations(2500)):
        assert ka == kb and len(oa.points) > 200
        np.testing.assert_allclose(ob.points, oa.points, atol=1e-5)


def test_track_command_on_exr_frames(pkg, folders, tmp_path):
    """``./run track --depth EXR_FOLDER --model``: the joints land on the ground truth as from the PNGs."""
    bench, png, exr = folders
    main = pkg("addon.cli.main").main
    outs = []
    for name, folder in (("png", png), ("exr", exr)):
        out = str(tmp_path / f"{name}.npz")
        assert main(["track", "--depth", folder, "--model", bench["model_path"], "--out", out]) == 0
        outs.append(out)
    from articula.solver.formats.bundle import load_bundle
    joints = []
    for out in outs:
        b = load_bundle(out)
        Rm, tm = forward_kinematics(b.model.skeleton, b.poses)
        heads = np.einsum("nbij,bj->nbi", Rm, b.model.skeleton.heads) + tm
        joints.append(heads[:, bench["joint_bones"]])
    np.testing.assert_allclose(joints[1], joints[0], atol=1e-4)
    assert np.median(np.linalg.norm(joints[1] - bench["joints"], axis=2)) < 0.05
