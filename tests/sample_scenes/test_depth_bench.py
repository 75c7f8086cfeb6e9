"""Depth-tracking benchmark recordings (sample_scenes.depth_bench): files, ground truth in view, caching."""
import os

import numpy as np

from articula.sample_scenes import depth_bench
from articula.sample_scenes.bone_roles import MAJOR_JOINT_LABELS
from articula.solver.depth import camera
from articula.solver.formats import png16
from articula.solver.formats.bundle import load_bundle
from articula.solver.rig import skinning
from articula.solver.rig.model import Poses


def test_tiny_recording_files_ground_truth_and_reuse(tmp_path):
    out = tmp_path / "rec"
    rec = depth_bench.bench_recording(out, subject_seed=1, resolution=(80, 60), frames=4, seed=2)
    assert not rec["reused"] and rec["seconds"] > 0
    names = sorted(os.listdir(out))
    assert names == [f"depth_{k:04d}.png" for k in range(4)] + ["ground_truth.npz", "intrinsics.json", "model.npz"]
    assert rec["depth_paths"][3] == str(out / "depth_0003.png") and rec["intrinsics"] == str(out / "intrinsics.json")
    intr = camera.load_intrinsics(rec["intrinsics"])
    assert (intr.width, intr.height, intr.name) == (80, 60, "kinect_v1")
    g = np.load(rec["ground_truth"])
    np.testing.assert_array_equal(rec["cam_to_world"], g["cam_to_world"][0])
    eye = rec["cam_to_world"][:3, 3]
    assert 2.5 <= -eye[1] + g["posed_heads"][:, 0, 1].mean() <= 3.1        # in front of the subject (-Y)
    # the ground-truth joints: bone heads of the exact model's poses, in world metres, inside the image
    joints = rec["joints"]
    assert joints.shape == (4, 14, 3) and rec["joint_labels"] == MAJOR_JOINT_LABELS
    np.testing.assert_array_equal(joints, g["posed_heads"][:, rec["joint_bones"]])
    uv, z = camera.project(camera.world_to_camera(joints.reshape(-1, 3), rec["cam_to_world"]), intr)
    assert (z > 2.0).all() and (z < 3.5).all()
    assert (uv > 0).all() and (uv[:, 0] < 79).all() and (uv[:, 1] < 59).all()
    # the joints sit on measured body pixels: the depth there is the body's, not the floor's
    depth = np.stack([png16.read_png16(p) for p in rec["depth_paths"]]) / 1000.0
    pix = np.rint(uv).astype(int).reshape(4, 14, 2)
    near = [depth[k, v - 1:v + 2, u - 1:u + 2] for k in range(4) for u, v in pix[k][[12, 13]]]   # neck, head
    assert all(np.abs(np.median(w[w > 0]) - zz) < 0.25 for w, zz in zip(near, z.reshape(4, 14)[:, [12, 13]].ravel()))
    # the returned model is the exact model: its hybrid skin of the true poses is the subject's surface
    model = rec["model"]
    poses = Poses(g["pose_rotations"], g["pose_translations"], g["pose_scales"])
    posed = skinning.hybrid_skin(model, poses)
    assert abs(posed[..., 2].min()) < 0.005                                  # on the floor at z = 0
    seen = g["visible_ids"][g["visible_offsets"][1]:g["visible_offsets"][2]]
    uv_seen, _ = camera.project(camera.world_to_camera(posed[1, seen], rec["cam_to_world"]), intr)
    assert len(seen) > 300 and (uv_seen >= -0.5).all() and (uv_seen[:, 0] <= 79.5).all()
    bundle = load_bundle(rec["model_path"])
    np.testing.assert_allclose(bundle.model.rest_vertices, model.rest_vertices)
    assert bundle.model.skeleton.names == model.skeleton.names and bundle.poses is None
    # the same parameters reuse the folder; other parameters render again
    stamp = os.path.getmtime(rec["depth_paths"][0])
    again = depth_bench.bench_recording(out, subject_seed=1, resolution=(80, 60), frames=4, seed=2)
    assert again["reused"] and again["seconds"] == 0 and os.path.getmtime(rec["depth_paths"][0]) == stamp
    np.testing.assert_array_equal(again["joints"], joints)
    other = depth_bench.bench_recording(out, subject_seed=1, resolution=(80, 60), frames=4, seed=2, turn_degrees=20)
    assert not other["reused"] and np.abs(other["joints"] - joints).max() > 0.01
    assert str(np.load(rec["ground_truth"])["bench_key"]) == depth_bench.bench_key(1, (80, 60), 4, 2, "cmu_mb", 20)
    shorter = depth_bench.bench_recording(out, subject_seed=1, resolution=(80, 60), frames=3, seed=2)
    assert not shorter["reused"] and sorted(p for p in os.listdir(out) if p.endswith(".png")) == \
        [f"depth_{k:04d}.png" for k in range(3)]                           # no frames left from before
