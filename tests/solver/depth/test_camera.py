"""Pinhole camera model: presets, intrinsics.json, projection / back-projection, extrinsics."""
import json
import math

import numpy as np
import pytest

from articula.solver.depth import camera
from articula.solver.depth.camera import Intrinsics
from articula.solver.errors import ArticulaInputError


def test_presets_are_valid_and_match_their_nominal_fov():
    for name, intr in camera.PRESETS.items():
        assert intr.validate() is intr and intr.name == name
    assert camera.PRESETS["kinect_v1"].fov_deg()[0] == pytest.approx(57.8, abs=0.3)
    assert camera.PRESETS["kinect_v2"].fov_deg() == pytest.approx((70.6, 60.0), abs=0.05)
    assert camera.PRESETS["azure_kinect_nfov"].fov_deg() == pytest.approx((75.0, 65.0), abs=0.05)
    assert camera.PRESETS["realsense_d435"].fov_deg() == pytest.approx((87.0, 58.0), abs=0.05)
    with pytest.raises(ArticulaInputError, match="unknown camera preset"):
        camera.preset("kinect_v9")


def test_with_resolution_keeps_the_field_point_of_each_pixel():
    full = camera.preset("kinect_v1")
    half = camera.preset("kinect_v1", (320, 240))
    pts = np.random.default_rng(0).uniform([-1, -1, 1], [1, 1, 4], (50, 3))
    uv_full, _ = camera.project(pts, full)
    uv_half, _ = camera.project(pts, half)
    np.testing.assert_allclose(uv_half, (uv_full + 0.5) * 0.5 - 0.5, atol=1e-12)
    assert half.fov_deg() == pytest.approx(full.fov_deg())


def test_json_round_trip_and_open3d_format(tmp_path):
    intr = camera.preset("realsense_d435")
    path = tmp_path / "intrinsics.json"
    camera.save_intrinsics(path, intr)
    assert json.loads(path.read_text())["format"] == camera.FORMAT
    assert camera.load_intrinsics(path) == intr
    o3d = {"width": 640, "height": 480, "intrinsic_matrix": [525.0, 0, 0, 0, 526.0, 0, 319.5, 239.5, 1]}
    path.write_text(json.dumps(o3d))
    got = camera.load_intrinsics(path)
    assert (got.fx, got.fy, got.cx, got.cy, got.width) == (525.0, 526.0, 319.5, 239.5, 640)


@pytest.mark.parametrize("change, message", [
    ({"fx": -1.0}, "fx must be positive"),
    ({"width": 0}, "width must be a positive integer"),
    ({"height": 480.5}, "height must be a positive integer"),
    ({"cy": float("nan")}, "cy must be a finite number"),
    ({"cx": 5000.0}, r"principal point \(cx, cy\) = \(5000, 239.5\) is outside the 640x480 image"),
    ({"format": "other/2"}, "unknown intrinsics format"),
])
def test_bad_intrinsics_files_name_file_and_key(tmp_path, change, message):
    path = tmp_path / "intrinsics.json"
    data = {"format": camera.FORMAT, "width": 640, "height": 480, "fx": 580.0, "fy": 580.0,
            "cx": 319.5, "cy": 239.5}
    data.update(change)
    path.write_text(json.dumps(data))
    with pytest.raises(ArticulaInputError, match=message) as err:
        camera.load_intrinsics(path)
    assert "intrinsics.json" in str(err.value)


def test_unreadable_or_incomplete_files(tmp_path):
    path = tmp_path / "intrinsics.json"
    path.write_text("{not json")
    with pytest.raises(ArticulaInputError, match="not valid JSON"):
        camera.load_intrinsics(path)
    path.write_text(json.dumps({"width": 640, "height": 480, "fx": 500.0}))
    with pytest.raises(ArticulaInputError, match="lack fy, cx, cy"):
        camera.load_intrinsics(path)
    with pytest.raises(ArticulaInputError, match="cannot read"):
        camera.load_intrinsics(tmp_path / "nope.json")


def test_depth_to_points_inverts_projection():
    intr = camera.preset("kinect_v1", (320, 240))
    rng = np.random.default_rng(1)
    depth = rng.uniform(0.5, 4.0, intr.shape)
    depth[rng.random(intr.shape) < 0.3] = 0.0
    depth[3, 4] = np.nan
    pts, idx = camera.depth_to_points(depth, intr)
    rows, cols = np.divmod(idx, intr.width)
    assert len(pts) == np.count_nonzero(np.isfinite(depth) & (depth > 0))
    uv, z = camera.project(pts, intr)
    np.testing.assert_allclose(uv, np.stack([cols, rows], 1), atol=1e-9)
    np.testing.assert_allclose(z, depth[rows, cols])
    np.testing.assert_allclose(camera.backproject(uv, z, intr), pts, atol=1e-12)
    with pytest.raises(ArticulaInputError, match="does not match"):
        camera.depth_to_points(depth[:, :-1], intr)


def test_back_projected_analytic_plane_is_planar():
    """Depth of the plane n.X = d along pixel rays is d / (n.r); the points must lie on it."""
    intr = camera.preset("kinect_v2")
    n, d = np.array([0.2, -0.3, 0.93]), 2.0
    n /= np.linalg.norm(n)
    u, v = camera.pixel_grid(intr)
    rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1)
    pts, _ = camera.depth_to_points(d / (rays @ n), intr)
    np.testing.assert_allclose(pts @ n, d, atol=1e-12)


def test_look_at_and_blender_convention():
    cam = camera.look_at(eye=(0.0, -3.0, 1.0), target=(0.0, 0.0, 1.0))
    np.testing.assert_allclose(cam[:3, :3] @ cam[:3, :3].T, np.eye(3), atol=1e-12)
    intr = camera.preset("kinect_v1")
    world = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.5, 0.0, 1.0]])
    uv, z = camera.project(camera.world_to_camera(world, cam), intr)
    np.testing.assert_allclose(uv[0], (intr.cx, intr.cy), atol=1e-9)   # target at the centre
    assert uv[1, 1] < intr.cy                                          # world up is image up
    assert uv[2, 0] > intr.cx                                          # +X right, seen from -Y
    np.testing.assert_allclose(z, 3.0)
    np.testing.assert_allclose(camera.camera_to_world(camera.world_to_camera(world, cam), cam), world)
    bl = camera.blender_from_cv(cam)
    np.testing.assert_allclose(-bl[:3, 2], [0, 1, 0], atol=1e-12)     # Blender looks down -Z
    np.testing.assert_allclose(bl[:3, 1], [0, 0, 1], atol=1e-12)      # and +Y is up
    np.testing.assert_allclose(camera.blender_from_cv(bl), cam)
    with pytest.raises(ArticulaInputError, match="parallel"):
        camera.look_at((0, 0, 3), (0, 0, 0))
    assert math.isclose(np.linalg.det(cam[:3, :3]), 1.0)


def test_camera_pose_round_trips_through_intrinsics_json(tmp_path):
    intr = camera.preset("kinect_v1", (320, 240))
    pose = camera.look_at(eye=(0.3, -2.7, 0.9), target=(0.1, 0.0, 0.95))
    path = tmp_path / "intrinsics.json"
    camera.save_intrinsics(path, intr)
    assert camera.load_camera_pose(path) is None                      # optional
    camera.save_intrinsics(path, intr, cam_to_world=pose)
    rows = json.loads(path.read_text())["cam_to_world"]
    assert len(rows) == 4 and all(len(r) == 4 for r in rows) and rows[3] == [0, 0, 0, 1]
    assert rows[0][3] == pytest.approx(0.3) and rows[1][3] == pytest.approx(-2.7)   # row-major: translation last
    np.testing.assert_array_equal(camera.load_camera_pose(path), pose)
    assert camera.load_intrinsics(path) == intr                       # the intrinsics read as before
    with pytest.raises(ArticulaInputError, match="cam_to_world is not rigid"):
        camera.save_intrinsics(path, intr, cam_to_world=np.diag([2.0, 2, 2, 1]))


def _rotated(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return [[c, -s, 0, 0.5], [s, c, 0, -2.0], [0, 0, 1, 1.0], [0, 0, 0, 1]]


@pytest.mark.parametrize("value, message", [
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], r"4x4 matrix .* got shape \(3, 3\)"),
    ("identity", "4x4 matrix"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], r"end with the row \[0, 0, 0, 1\]"),
    ([[1, 0, 0, float("nan")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "NaN or infinite"),
    ([[1.001, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "not rigid"),
    ([[1, 0.01, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "not rigid"),
    ([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "reflection"),
])
def test_bad_camera_poses_name_file_and_key(tmp_path, value, message):
    path = tmp_path / "intrinsics.json"
    data = {"format": camera.FORMAT, "width": 640, "height": 480, "fx": 580.0, "fy": 580.0,
            "cx": 319.5, "cy": 239.5, "cam_to_world": value}
    path.write_text(json.dumps(data))
    with pytest.raises(ArticulaInputError, match=message) as err:
        camera.load_camera_pose(path)
    assert "intrinsics.json" in str(err.value) and "cam_to_world" in str(err.value)
    data["cam_to_world"] = _rotated(30.0)                             # rounded to JSON's precision: accepted
    data["cam_to_world"][0][0] += 5e-5
    path.write_text(json.dumps(data))
    assert camera.load_camera_pose(path)[1, 3] == -2.0
