"""Every projection and back-projection of the depth tools with fx != fy and a principal point off the
image centre, against a brute-force pinhole model (K written out by hand; one point or pixel at a time):
the importer's pixel rays, the tracker's view camera and depth image, the intrinsics' rescaling and the
sample-data renderer.  A camera with fx = fy and a central principal point hides a swapped fx/fy or cx/cy."""
import numpy as np

from articula.solver.depth import camera
from articula.solver.depth import frames as dp
from articula.solver.track_depth.observation import ViewCamera, depth_image

FX, FY, CX, CY, W, H = 410.0, 530.0, 190.3, 101.7, 320, 240
INTR = camera.Intrinsics(W, H, FX, FY, CX, CY, name="anisotropic").validate()
K = np.array([[410.0, 0.0, 190.3], [0.0, 530.0, 101.7], [0.0, 0.0, 1.0]])


def _project(p):
    """Brute force: one point at a time through K."""
    out = []
    for x in p:
        h = K @ x
        out.append((h[0] / h[2], h[1] / h[2]))
    return np.array(out)


def _backproject(u, v, z):
    """Brute force: the point at depth z on the ray through pixel (u, v), solving K x = z (u, v, 1)."""
    return np.linalg.solve(K, z * np.array([u, v, 1.0]))


def _points(n=200, seed=0):
    """Points in front of the camera that project inside the image."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform([0, 0], [W - 1, H - 1], (n, 2))
    z = rng.uniform(0.8, 4.0, n)
    return np.array([_backproject(u, v, d) for (u, v), d in zip(uv, z)]), uv


def test_project_and_backproject():
    p, uv = _points()
    got, z = camera.project(p, INTR)
    np.testing.assert_allclose(got, _project(p), atol=1e-9)
    np.testing.assert_allclose(got, uv, atol=1e-9)
    np.testing.assert_allclose(camera.backproject(uv, z, INTR), p, atol=1e-9)


def test_depth_image_to_points_and_pixel_rays():
    """The importer's back-projections (``depth_to_points``; ``pixel_rays`` + ``backproject_grid``, which
    ``frames.process_depth`` and the tracker's ``observe`` use) give each pixel's brute-force point."""
    rng = np.random.default_rng(2)
    depth = rng.uniform(0.5, 4.0, (H, W))
    pts, idx = camera.depth_to_points(depth, INTR)
    grid = dp.backproject_grid(depth.astype(np.float32), dp.pixel_rays(INTR))
    for k in rng.choice(len(idx), 300, replace=False):
        v, u = divmod(int(idx[k]), W)
        want = _backproject(u, v, depth[v, u])
        np.testing.assert_allclose(pts[k], want, atol=1e-9)
        np.testing.assert_allclose(grid[v, u], want, rtol=1e-5, atol=1e-6)


def test_tracker_view_camera_and_depth_image():
    """The tracker's camera (a rotated, moved ``cam_to_world``) projects world points where K does, and its
    depth image puts each camera-frame point on its brute-force pixel."""
    p, uv = _points(seed=3)
    c2w = camera.look_at([0.3, -2.0, 1.1], [0.1, 0.5, 0.9])
    world = camera.camera_to_world(p, c2w)
    got, z = ViewCamera(INTR, c2w).project(world)
    np.testing.assert_allclose(got, uv, atol=1e-8)
    np.testing.assert_allclose(z, p[:, 2], atol=1e-9)
    img = depth_image(p, INTR)
    pix = np.round(_project(p)).astype(int)
    for (u, v), d in zip(pix, p[:, 2]):
        assert img[v, u] <= d + 1e-6
    nearest = {}
    for (u, v), d in zip(pix, p[:, 2]):
        nearest[(u, v)] = min(d, nearest.get((u, v), np.inf))
    filled = np.argwhere(np.isfinite(img))
    assert len(filled) == len(nearest)
    for (u, v), d in nearest.items():
        assert abs(img[v, u] - d) < 1e-6


def test_rescaled_intrinsics_keep_each_pixel_ray():
    """Half the resolution in x only: the ray through a pixel centre of the small image is the ray through
    the same field point of the full image."""
    small = INTR.with_resolution(W // 2, H)
    for u, v in [(0.0, 0.0), (37.0, 201.0), (W // 2 - 1, H - 1)]:
        ray_small = camera.backproject(np.array([[u, v]]), np.array([1.0]), small)[0]
        full_u = (u + 0.5) * 2 - 0.5
        np.testing.assert_allclose(ray_small, _backproject(full_u, v, 1.0), atol=1e-12)


def test_sample_renderer_puts_a_point_on_its_pixel():
    """The synthetic recordings' renderer: a small square facing the camera centred on a brute-force
    back-projected pixel is seen at that pixel, at its depth."""
    from articula.sample_scenes.depth_render import render_depth
    for u, v, d in [(40, 200, 2.0), (280, 30, 3.0)]:
        c = _backproject(u, v, d)
        s = 0.004 * d
        verts = c + np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]])
        depth, _ = render_depth(verts, np.array([[0, 1, 2], [0, 2, 3]]), INTR)
        rows, cols = np.nonzero(depth > 0)
        assert len(rows) > 0
        assert abs(rows.mean() - v) <= 1.0 and abs(cols.mean() - u) <= 1.0
        np.testing.assert_allclose(depth[v, u], d, atol=1e-9)
