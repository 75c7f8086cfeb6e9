"""Depth processing against exact synthetic scenes (analytic ray casting in sample_scenes/depth_scene.py)."""
import math

import numpy as np
import pytest

from articula.solver.depth import camera
from articula.solver.depth import frames as dp
from articula.solver.depth import recording as ps
from articula.solver.errors import ArticulaInputError
from articula.solver.formats.point_files import PointSequence
from articula.solver.formats.png16 import write_png16

from articula.sample_scenes.depth_scene import floor_box_scene, sphere_depth

INTR = camera.Intrinsics(160, 120, 140.0, 138.0, 81.3, 58.2)


def opts(**kw):
    base = dict(depth_min=0.2, depth_max=8.0, remove_floor=False, estimate_normals=False)
    base.update(kw)
    return dp.DepthOptions(**base)


def test_backprojection_matches_camera_module():
    depth, _, _ = floor_box_scene(INTR)
    grid = dp.backproject_grid(np.where(depth > 0, depth, np.nan), dp.pixel_rays(INTR))
    ref, idx = camera.depth_to_points(depth, INTR)
    rows, cols = np.divmod(idx, INTR.width)
    np.testing.assert_allclose(grid[rows, cols], ref, rtol=2e-6, atol=2e-6)


def test_floor_ransac_recovers_plane_and_keeps_the_box():
    depth, c2w, label = floor_box_scene(INTR)
    z = np.where(depth > 0, depth, np.nan).astype(np.float32)
    rays = dp.pixel_rays(INTR)
    grid = dp.backproject_grid(z, rays)
    pts = grid[np.isfinite(z)]
    plane, inliers = dp.ransac_plane(pts, 0.02, seed=3)
    # true floor in the camera frame: world z = 0  <=>  n_w . p_w = 0 with p_w = R p + eye
    n_true = c2w[:3, :3].T @ np.array([0, 0, 1.0])
    d_true = c2w[2, 3]
    assert math.degrees(math.acos(min(1, plane[0] @ n_true))) < 0.05
    assert abs(plane[1] - d_true) < 1e-3
    # the floor is removed, exactly the box pixels above the tolerance remain
    fp = dp.process_depth(z, rays, opts(depth_noise=0.0), floor=plane)
    world = fp.points @ c2w[:3, :3].T + c2w[:3, 3]
    assert len(fp.points) > 300
    assert (world[:, 2] >= 0.02 - 1e-3).all()
    assert (np.abs(world[:, 0]) <= 0.25 + 1e-4).all() and (world[:, 1] >= 2.2 - 1e-4).all()
    u, v = fp.pixels.T.astype(int)
    assert (label[v, u] == 2).all()
    expected = ((label == 2) & (np.einsum("hwi,i->hw", grid, plane[0]) + plane[1] >= 0.02)).sum()
    assert len(fp.points) == expected


def test_floor_tolerance_follows_depth_noise():
    """Kinect-like depth noise sigma = 0.002 z^2 along the rays: a fixed 2 cm tolerance leaves far floor
    points, the noise term (0.01 z^2 = 5 sigma along the ray, projected on the floor normal) removes
    all but a few tail samples."""
    depth, c2w, label = floor_box_scene(INTR, box=None)
    rng = np.random.default_rng(5)
    z = np.where((depth > 0) & (depth < 6.0), depth, np.nan)     # a sensor's range
    z = (z + rng.normal(size=z.shape) * 0.002 * z ** 2).astype(np.float32)
    grid = dp.backproject_grid(z, dp.pixel_rays(INTR))
    floor = (c2w[:3, :3].T @ np.array([0, 0, 1.0]), c2w[2, 3])
    fixed = dp.frame_mask(z, grid, opts(depth_noise=0.0), floor=floor)
    scaled = dp.frame_mask(z, grid, opts(), floor=floor)
    n = np.isfinite(z).sum()
    assert fixed.sum() > 0.01 * n          # 2 cm alone leaves the far floor
    assert scaled.sum() <= 0.0005 * n


def test_floor_tilt_constraint_ignores_a_wall():
    depth, c2w, label = floor_box_scene(INTR, box=None, wall_y=3.0, target=(0, 3, 1.0))
    z = np.where(depth > 0, depth, np.nan)
    pts = dp.backproject_grid(z, dp.pixel_rays(INTR))[np.isfinite(z)]
    assert (label == 3).sum() > (label == 1).sum()   # the wall is the bigger plane
    plane, _ = dp.ransac_plane(pts, 0.02, max_tilt_deg=45)
    n_true = c2w[:3, :3].T @ np.array([0, 0, 1.0])
    assert plane[0] @ n_true > 0.9999
    world = dp.world_from_sensor(plane)
    # camera sits 1.2 m above the recovered floor, on the world Z axis
    np.testing.assert_allclose(world[:3, 3], [0, 0, 1.2], atol=1e-3)


def test_world_from_sensor_reproduces_the_scene_frame():
    depth, c2w, label = floor_box_scene(INTR)
    z = np.where(depth > 0, depth, np.nan)
    pts = dp.backproject_grid(z, dp.pixel_rays(INTR))[np.isfinite(z)].astype(np.float64)
    plane, _ = dp.ransac_plane(pts, 0.01)
    m = dp.world_from_sensor(plane)
    # camera at x = y = 0 looking along +Y: the recovered world frame is the scene's
    np.testing.assert_allclose(m, c2w, atol=2e-3)
    np.testing.assert_allclose(np.linalg.det(m[:3, :3]), 1.0, atol=1e-9)


def test_no_plane_when_nothing_is_level():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(3000, 3)) * 0.2 + [0, 0, 2]
    plane, _ = dp.ransac_plane(pts, 0.005, max_tilt_deg=30)
    if plane is not None:  # a random near-level triple can pass; it must then hold few points
        assert (np.abs(dp.plane_distance(pts, plane)) < 0.005).mean() < 0.05


def test_voxel_downsample_counts_and_means_on_a_lattice():
    g = np.stack(np.meshgrid(np.arange(8), np.arange(6), np.arange(4), indexing="ij"), -1).reshape(-1, 3)
    pts = (g * 0.01 + 0.0025).astype(np.float32)          # 192 points, 2x2x2 per 0.02 voxel
    col = g.astype(np.float32)
    out, oc = dp.voxel_downsample(pts, 0.02, col)
    assert len(out) == 192 // 8
    np.testing.assert_allclose(np.sort(out[:, 0]), np.sort(np.repeat(np.arange(4) * 0.02 + 0.0075, 6)), atol=1e-6)
    np.testing.assert_allclose(oc, (out - 0.0025) / 0.01, atol=1e-4)  # attributes averaged the same way
    out2, = dp.voxel_downsample(pts, 0.04)
    assert len(out2) == 2 * 2 * 1  # x 0..7 -> 2 bins, y 0..5 -> 2, z 0..3 -> 1


def test_grid_normals_of_a_plane_and_a_sphere():
    n = np.array([0.3, -0.5, -1.0]); n /= np.linalg.norm(n)   # faces the camera
    d = 1.7
    u, v = camera.pixel_grid(INTR)
    r = np.stack(((u - INTR.cx) / INTR.fx, (v - INTR.cy) / INTR.fy, np.ones_like(u)), -1)
    z = -d / (r @ n)
    grid = dp.backproject_grid(z, dp.pixel_rays(INTR))
    normals = dp.grid_normals(grid)
    assert np.abs(normals.reshape(-1, 3) @ n - 1).max() < 1e-4
    # sphere: normals point from the centre to the surface point (central differences: well under a degree)
    c = np.array([0.1, -0.05, 1.5])
    zs = sphere_depth(INTR, c, 0.3)
    g = dp.backproject_grid(np.where(zs > 0, zs, np.nan), dp.pixel_rays(INTR))
    ns = dp.grid_normals(g)
    inside = zs > 0
    ref = g[inside] - c
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    cos = (ns[inside] * ref).sum(1)
    assert np.median(cos) > math.cos(math.radians(1.0))
    assert np.percentile(cos, 95) > math.cos(math.radians(3.0))   # rim pixels use one-sided differences


def test_pca_normals_of_a_noisy_plane_face_the_sensor():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.5, 0.5, size=(2000, 2))
    n = np.array([0.0, -0.6, -0.8])
    e1 = np.array([1.0, 0, 0]); e2 = np.cross(n, e1)
    pts = 2.0 * -n + xy[:, :1] * e1 + xy[:, 1:] * e2 + rng.normal(scale=0.001, size=(2000, 1)) * n
    normals = dp.pca_normals(pts, k=12)
    assert np.median(normals @ n) > 0.999
    assert (normals @ n > 0.98).all()


def test_background_subtraction_keeps_only_the_new_object():
    bg, _, _ = floor_box_scene(INTR, box=None, wall_y=3.5)
    fg, _, label = floor_box_scene(INTR, wall_y=3.5)
    o = opts(subtract_background=True)
    rays = dp.pixel_rays(INTR)
    zb = dp.depth_in_metres((bg * 1000).round().astype(np.uint16), o)
    zf = dp.depth_in_metres((fg * 1000).round().astype(np.uint16), o)
    fp = dp.process_depth(zf, rays, o, background=zb)
    u, v = fp.pixels.T.astype(int)
    assert (label[v, u] == 2).all()
    # the box's pixels that are more than the tolerance in front of the background are all kept
    margin = o.background_tolerance + o.depth_noise * zb ** 2
    assert len(fp.points) == ((label == 2) & (zf < zb - margin)).sum()
    # a median over frames in which the box moves recovers the empty scene
    frames = [floor_box_scene(INTR, box=((x - .2, 2.2, 0), (x + .2, 2.6, .8)), wall_y=3.5)[0] for x in (-1.2, 0.0, 1.2)]
    med = dp.median_background([np.where(f > 0, f, np.nan) for f in frames])
    ok = np.isfinite(med)
    assert np.abs(med[ok] - bg[ok]).max() < 1e-6  # float32


@pytest.mark.filterwarnings("ignore:All-NaN slice")   # the reference's warning for the never-valid pixel
def test_median_background_equals_nanmedian():
    rng = np.random.default_rng(4)
    for frames in (1, 2, 5, 6):
        stack = rng.uniform(0.5, 4, size=(frames, 30, 40)).astype(np.float32)
        stack[rng.random(stack.shape) < 0.4] = np.nan
        stack[:, 0, 0] = np.nan                                   # never valid
        ref = np.nanmedian(stack, axis=0) if frames > 1 else stack[0]
        got = dp.median_background(stack if frames > 1 else stack[0])
        np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
        np.testing.assert_allclose(got[~np.isnan(ref)], ref[~np.isnan(ref)], rtol=1e-6)


def test_frames_with_another_resolution_rescale_the_intrinsics():
    depth, _, _ = floor_box_scene(INTR.with_resolution(80, 60))
    folder_raw = (depth * 1000).round().astype(np.uint16)
    frame = ps.DepthFrame("small.png", lambda: folder_raw)
    seq = ps.import_depth([frame], INTR, opts())
    assert any("rescaled" in n for n in seq.notes)
    small = INTR.with_resolution(80, 60)
    assert seq.intrinsics == (80, 60, small.fx, small.fy, small.cx, small.cy)
    uv, _ = camera.project(seq.points, small)
    np.testing.assert_allclose(uv, np.round(uv), atol=1e-3)
    with pytest.raises(ArticulaInputError, match="small.png: 80x60 pixels, but the intrinsics"):
        ps.import_depth([frame], camera.Intrinsics(160, 100, 140.0, 138.0, 80, 50), opts())


def test_range_clip_and_colours():
    depth, _, _ = floor_box_scene(INTR, wall_y=3.5)
    raw = (depth * 1000).round().astype(np.uint16)
    o = opts(depth_min=1.0, depth_max=3.0)
    z = dp.depth_in_metres(raw, o)
    color = np.zeros((INTR.height * 2, INTR.width * 2, 3), np.float32)
    color[..., 0] = np.arange(INTR.width * 2)[None, :] // 2   # column of the depth pixel
    color[..., 1] = np.arange(INTR.height * 2)[:, None] // 2
    fp = dp.process_depth(z, dp.pixel_rays(INTR), o, color=color)
    assert (fp.points[:, 2] >= 1.0).all() and (fp.points[:, 2] <= 3.0).all()
    assert len(fp.points) == ((raw >= 1000) & (raw <= 3000)).sum()
    np.testing.assert_array_equal(fp.colors[:, :2], fp.pixels)


# ---------------------------------------------------------------------------- files and sequences

def box_x(k, n):
    return -0.6 + 1.2 * k / max(n - 1, 1)


def write_recording(folder, n=4, intr=INTR):
    folder.mkdir(exist_ok=True)
    for k in range(n):
        x = box_x(k, n)
        depth, c2w, _ = floor_box_scene(intr, box=((x - .2, 2.2, 0), (x + .2, 2.6, .8)))
        write_png16(folder / f"depth_{k}.png", (depth * 1000).round().astype(np.uint16))
    return c2w


def test_sequence_from_pngs_with_floor_and_cache_roundtrip(tmp_path):
    c2w = write_recording(tmp_path / "rec", n=12)
    paths = ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)
    assert [p.rsplit("_", 1)[1] for p in paths[:3]] == ["0.png", "1.png", "2.png"]   # natural order
    o = opts(remove_floor=True, estimate_normals=True)
    seq = ps.import_depth(ps.png_frames(paths), INTR, o)
    assert seq.frame_count == 12 and seq.floor is not None
    np.testing.assert_allclose(seq.world_from_sensor, c2w, atol=5e-3)   # mm quantisation
    for k in range(12):
        pts = seq.points[seq.frame(k)]
        w = pts @ seq.world_from_sensor[:3, :3].T + seq.world_from_sensor[:3, 3]
        x = box_x(k, 12)
        assert len(pts) > 100
        assert (np.abs(w[:, 0] - x) < 0.2 + 5e-3).all() and (w[:, 2] > 0.01).all()
    seq.save(str(tmp_path / "c.npz"))
    back = PointSequence.load(str(tmp_path / "c.npz"))
    np.testing.assert_array_equal(back.points, seq.points)
    np.testing.assert_array_equal(back.offsets, seq.offsets)
    np.testing.assert_array_equal(back.normals, seq.normals)
    assert back.frame_names == [p.rsplit("/", 1)[1] for p in paths]
    np.testing.assert_allclose(back.floor[0], seq.floor[0])


def test_bad_depth_inputs_name_the_file(tmp_path):
    with pytest.raises(ArticulaInputError, match="no frames found"):
        ps.list_frames(str(tmp_path), ps.DEPTH_EXTENSIONS)
    write_recording(tmp_path / "rec", n=2)
    write_png16(tmp_path / "rec" / "depth_2.png", np.zeros((60, 80), np.uint16))
    with pytest.raises(ArticulaInputError, match=r"depth_2.png: 80x60 pixels, but depth_0.png is 160x120"):
        ps.import_depth(ps.png_frames(ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)), INTR, opts())
    write_png16(tmp_path / "rec" / "depth_2.png", np.zeros((120, 160), np.uint8))
    with pytest.raises(ArticulaInputError, match=r"depth_2.png: 8-bit PNG"):
        ps.import_depth(ps.png_frames(ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)), INTR, opts())
    (tmp_path / "rec" / "depth_2.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(ArticulaInputError, match=r"depth_2.png"):
        ps.import_depth(ps.png_frames(ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)), INTR, opts())
    with pytest.raises(ArticulaInputError, match=r"depth_0.png: 160x120 pixels, but the intrinsics .custom. are for 100x100"):
        ps.import_depth(ps.png_frames(ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)[:1]),
                        camera.Intrinsics(100, 100, 90.0, 90.0, 50.0, 50.0), opts())


def test_point_cloud_sequence_from_files(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.uniform([-1, -1, 1], [1, 1, 3], size=(500, 3))
    np.save(tmp_path / "f_0.npy", a)
    seq = ps.import_clouds([str(tmp_path / "f_0.npy")] * 2, opts(voxel_size=0.2, estimate_normals=True))
    assert seq.frame_count == 2 and seq.normals.shape == seq.points.shape
    assert len(seq.points[seq.frame(0)]) < 500


def test_threaded_import_equals_sequential_and_reports_the_first_bad_frame(tmp_path):
    write_recording(tmp_path / "rec", n=19)
    paths = ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)
    o = dict(remove_floor=True, estimate_normals=True, voxel_size=0.02, subtract_background=True)
    one = ps.import_depth(ps.png_frames(paths), INTR, opts(workers=1, **o))
    three = ps.import_depth(ps.png_frames(paths), INTR, opts(workers=3, **o))
    np.testing.assert_array_equal(one.offsets, three.offsets)
    np.testing.assert_array_equal(one.points, three.points)
    np.testing.assert_array_equal(one.normals, three.normals)
    write_png16(paths[17], np.zeros((120, 160), np.uint8))
    write_png16(paths[11], np.zeros((60, 80), np.uint16))   # frame 11 is in the second chunk of 8
    with pytest.raises(ArticulaInputError, match=r"depth_11.png: 80x60 pixels"):
        ps.import_depth(ps.png_frames(paths), INTR, opts(workers=3))


def test_cancelling_stops_the_threaded_import(tmp_path):
    from articula.solver.errors import Cancelled
    write_recording(tmp_path / "rec", n=40)
    paths = ps.list_frames(str(tmp_path / "rec"), ps.DEPTH_EXTENSIONS)
    calls = []

    def progress(fraction, text=""):
        calls.append(fraction)
        if fraction > 0.3:
            raise Cancelled("test")
    with pytest.raises(Cancelled):
        ps.import_depth(ps.png_frames(paths), INTR, opts(workers=3), progress)
    assert max(calls) < 0.6
