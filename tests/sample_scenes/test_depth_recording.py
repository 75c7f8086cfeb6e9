"""Synthetic depth recordings: files, geometry read back through the public readers, ground truth,
determinism; mesh writers read back by the scan readers."""
import json
import os

import numpy as np
import pytest
import trimesh

from articula.sample_scenes import depth_noise as dn
from articula.sample_scenes import depth_recording as rec
from articula.solver.depth import camera
from articula.solver.formats import png16
from articula.solver.errors import ArticulaInputError

RADIUS = 0.35


def _moving_sphere(n=3):
    s = trimesh.creation.icosphere(subdivisions=3, radius=RADIUS)
    centres = np.array([[0.1 * k, 0.05 * k, 1.0] for k in range(n)])
    return s.vertices[None] + centres[:, None], np.asarray(s.faces), centres


def test_noiseless_recording_reproduces_the_scene(tmp_path):
    frames, faces, centres = _moving_sphere()
    gt = {"centres": centres, "names": np.array(["ball"])}
    out = tmp_path / "rec"
    info = rec.generate_depth(out, frames, faces, gt, resolution=(160, 120), noise=dn.NOISELESS,
                              floor=True, background=True, seed=3, save_clean=True, save_vertices=True)
    assert info["frames"] == 3
    names = sorted(os.listdir(out))
    assert names == ["depth_0000.png", "depth_0001.png", "depth_0002.png", "ground_truth.npz", "intrinsics.json"]
    intr = camera.load_intrinsics(out / "intrinsics.json")
    assert (intr.width, intr.height) == (160, 120)
    g = np.load(out / "ground_truth.npz")
    assert str(g["format"]) == rec.GT_FORMAT and json.loads(str(g["noise_params"]))["quantization"] == "none"
    np.testing.assert_allclose(g["centres"], centres)
    np.testing.assert_array_equal(camera.load_camera_pose(out / "intrinsics.json"), g["cam_to_world"][0])
    floor_z = frames[:, :, 2].min()
    for k in range(3):
        depth_m = png16.read_png16(out / f"depth_{k:04d}.png") * intr.depth_unit_m
        np.testing.assert_array_equal(png16.read_png16(out / f"depth_{k:04d}.png"), g["clean_depth_mm"][k])
        pts, _ = camera.depth_to_points(depth_m, intr)
        world = camera.camera_to_world(pts, g["cam_to_world"][k])
        r = np.linalg.norm(world - centres[k], axis=1)
        on_ball = (r < RADIUS + 0.05) & (world[:, 2] > floor_z + 0.01)
        # sphere points: between the inscribed polyhedron and the sphere, +-0.5 mm rounding (x slant)
        assert on_ball.sum() > 500
        assert r[on_ball].max() < RADIUS + 0.002 and r[on_ball].min() > RADIUS * 0.985
        rest = world[~on_ball]
        on_floor = np.abs(rest[:, 2] - floor_z) < 0.01
        assert on_floor.sum() > 500
        # the wall: a vertical plane 1.5 m behind the subject centre (camera in front, on -Y)
        wall_y = (frames[:, :, 1].min() + frames[:, :, 1].max()) / 2 + 1.5
        assert (~on_floor).sum() > 500
        assert np.all(np.abs(rest[~on_floor, 1] - wall_y) < 0.005)
        # visible vertices: the hemisphere facing the camera
        vis = rec.ragged(g["visible_ids"], g["visible_offsets"], k)
        eye = g["cam_to_world"][k][:3, 3]
        facing = np.einsum("ij,ij->i", frames[k] - centres[k], eye - frames[k]) > 0
        assert set(np.flatnonzero(facing)) >= set(vis) - set(np.flatnonzero(~facing)) and \
            facing[vis].mean() > 0.9 and len(vis) > 0.3 * facing.sum()
    np.testing.assert_allclose(g["vertices"], frames.astype(np.float32))
    bl = g["blender_camera_matrix"][0]
    np.testing.assert_allclose(-bl[:3, 2], g["cam_to_world"][0][:3, 2])


def test_noisy_recording_is_deterministic_and_seed_dependent(tmp_path):
    frames, faces, _ = _moving_sphere(2)
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        rec.generate_depth(tmp_path / name, frames, faces, resolution=(64, 48), seed=seed)
    read = lambda d, k: (tmp_path / d / f"depth_{k:04d}.png").read_bytes()  # noqa: E731
    assert read("a", 1) == read("b", 1) and read("a", 1) != read("c", 1)
    depth = png16.read_png16(tmp_path / "a" / "depth_0000.png")
    assert (depth > 0).mean() > 0.1 and depth.max() < 4500


def test_bad_inputs(tmp_path):
    frames, faces, _ = _moving_sphere(1)
    with pytest.raises(ArticulaInputError, match="frames must be"):
        rec.generate_depth(tmp_path, frames[0], faces)
    with pytest.raises(ArticulaInputError, match="faces must be"):
        rec.generate_depth(tmp_path, frames, faces + 10_000)
    with pytest.raises(ArticulaInputError, match="unknown camera preset"):
        rec.generate_depth(tmp_path, frames, faces, camera="webcam")



def test_camera_placement_height_above_floor():
    frames, faces, _ = _moving_sphere(1)
    floor_z = frames[..., 2].min()
    c2w = rec.CameraPlacement(distance=2.0, height=1.3, azimuth_deg=90).cam_to_world([0.0, 0.0, 1.0], floor_z)
    np.testing.assert_allclose(c2w[:3, 3], [2.0, 0.0, floor_z + 1.3], atol=1e-12)
    np.testing.assert_allclose(c2w[:2, 2] / np.linalg.norm(c2w[:2, 2]), [-1.0, 0.0], atol=1e-12)
