"""z-buffer rasteriser against analytic depth (planes, spheres) and independent ray casting."""
import numpy as np
import pytest

from articula.sample_scenes import depth_render as dr
from articula.solver.depth import camera
from articula.solver.errors import ArticulaInputError


def _grid_plane(origin, e1, e2, n=12):
    """A planar n x n quad grid (2 n^2 triangles) spanning origin + [0,1] e1 + [0,1] e2."""
    s = np.linspace(0.0, 1.0, n + 1)
    a, b = np.meshgrid(s, s, indexing="ij")
    verts = origin + a.reshape(-1, 1) * e1 + b.reshape(-1, 1) * e2
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    i = i.ravel()
    faces = np.concatenate([np.stack([i, i + n + 1, i + 1], 1), np.stack([i + 1, i + n + 1, i + n + 2], 1)])
    return verts, faces


def _rays(intr):
    u, v = camera.pixel_grid(intr)
    return np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1)


def _icosphere(subdiv):
    """Unit icosphere by repeated midpoint subdivision (test-local, independent of the code under test)."""
    t = (1 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
         [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdiv):
        cache, new = {}, []

        def mid(i, j):
            key = (min(i, j), max(i, j))
            if key not in cache:
                m = verts[i] + verts[j]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = new
    return np.array(verts), np.array(f)


def _ray_cast(rays, verts, faces):
    """Nearest hit (t = depth, since rays have z = 1) and face id by Moller-Trumbore, brute force."""
    r = rays.reshape(-1, 3)
    p0, e1, e2 = verts[faces[:, 0]], verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]]
    pvec = np.cross(r[:, None, :], e2[None])
    det = np.einsum("rfk,fk->rf", pvec, e1)
    inv = 1.0 / np.where(np.abs(det) > 1e-15, det, np.nan)
    tvec = -p0[None]
    u = np.einsum("rfk,rfk->rf", np.broadcast_to(tvec, pvec.shape), pvec) * inv
    qvec = np.cross(np.broadcast_to(tvec, pvec.shape), e1[None])
    v = np.einsum("rk,rfk->rf", r, qvec) * inv
    t = np.einsum("fk,rfk->rf", e2, qvec) * inv
    hit = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (t > 0)
    t = np.where(hit, t, np.inf)
    best = np.argmin(t, axis=1)
    depth = t[np.arange(len(r)), best]
    return np.where(np.isfinite(depth), depth, 0.0).reshape(rays.shape[:2]), \
        np.where(np.isfinite(depth), best, -1).reshape(rays.shape[:2])


def test_tilted_plane_matches_analytic_depth_without_holes():
    intr = camera.preset("kinect_v1", (320, 240))
    n, d = np.array([0.25, -0.4, 1.0]), 2.5
    # a grid plane on n.X = d, larger than the view
    e1, e2 = np.array([1.0, 0.0, -0.25]), np.array([0.0, 1.0, 0.4])
    origin = np.array([-4.0, -4.0, 0.0])
    origin[2] = (d - n[:2] @ origin[:2]) / n[2]
    verts, faces = _grid_plane(origin, 8 * e1, 8 * e2, n=15)
    assert np.allclose(verts @ n, d)
    depth, tri = dr.render_depth(verts, faces, intr)
    expected = d / (_rays(intr) @ n)
    assert (tri >= 0).all() and (depth > 0).all()              # watertight: every pixel covered
    assert np.abs(depth - expected).max() < 1e-6
    cos = dr.incidence_cosine(verts, faces, tri, intr)
    rays = _rays(intr)
    ref = np.abs(rays @ n) / np.linalg.norm(rays, axis=-1) / np.linalg.norm(n)
    np.testing.assert_allclose(cos, ref, atol=1e-9)


def test_sphere_matches_ray_casting_and_analytic_sphere():
    intr = camera.preset("kinect_v1", (80, 60))
    unit, faces = _icosphere(2)
    radius, centre = 0.6, np.array([0.1, -0.05, 2.0])
    verts = unit * radius + centre
    depth, tri = dr.render_depth(verts, faces, intr)
    ref_depth, ref_tri = _ray_cast(_rays(intr), verts, faces)
    assert np.count_nonzero((depth > 0) != (ref_depth > 0)) <= 2   # silhouette (edge ties only)
    both = (depth > 0) & (ref_depth > 0)
    assert both.sum() > 500
    assert np.abs(depth[both] - ref_depth[both]).max() < 1e-9
    # the seen triangle is the one hit (up to ties on shared edges, which have equal depth)
    assert (tri[both] == ref_tri[both]).mean() > 0.97
    # analytic sphere: the inscribed polyhedron lies between the face-plane radius and the sphere
    rays = _rays(intr)
    oc = rays @ centre
    rr = np.einsum("ijk,ijk->ij", rays, rays)
    disc = oc ** 2 - rr * (centre @ centre - radius ** 2)
    analytic = np.where(disc > 0, (oc - np.sqrt(np.maximum(disc, 0))) / rr, 0.0)
    normals = dr.face_normals(verts, faces)
    r_in = np.min(np.einsum("ij,ij->i", normals, verts[faces[:, 0]] - centre))
    facing = both & (dr.incidence_cosine(verts, faces, tri, intr) > 0.5) & (disc > 0)
    err = depth[facing] - analytic[facing]
    assert err.min() > -1e-9                                   # never in front of the true sphere
    assert err.max() < 2 * (radius - r_in) / 0.5


def test_occlusion_nearest_wins_and_visible_vertices():
    intr = camera.preset("kinect_v1", (64, 48))
    far_v, far_f = _grid_plane(np.array([-2.0, -2.0, 3.0]), np.array([4.0, 0, 0]), np.array([0, 4.0, 0]), 2)
    near_v, near_f = _grid_plane(np.array([-0.2, -0.2, 1.0]), np.array([0.4, 0, 0]), np.array([0, 0.4, 0]), 2)
    verts = np.concatenate([near_v, far_v])
    faces = np.concatenate([near_f, far_f + len(near_v)])
    depth, tri = dr.render_depth(verts, faces, intr)
    near_px = tri < len(near_f)
    assert near_px.sum() > 50 and np.allclose(depth[near_px], 1.0) and np.allclose(depth[~near_px], 3.0)
    # visible subject vertices (the near square's), the far plane's excluded by n_faces
    vis = dr.visible_vertices(tri, faces, n_faces=len(near_f))
    assert set(vis) == set(range(len(near_v)))
    # move the near square behind the far plane: it disappears
    verts2 = np.concatenate([near_v + [0, 0, 5.0], far_v])
    _, tri2 = dr.render_depth(verts2, faces, intr)
    assert (tri2 >= len(near_f)).all()
    assert dr.visible_vertices(tri2, faces, n_faces=len(near_f)).size == 0


def test_behind_camera_and_bad_input():
    intr = camera.preset("kinect_v1", (32, 24))
    verts = np.array([[0, 0, -1.0], [1, 0, -1.0], [0, 1, -1.0]])
    depth, tri = dr.render_depth(verts, np.array([[0, 1, 2]]), intr)
    assert not depth.any() and (tri == -1).all()
    with pytest.raises(ArticulaInputError, match="out of range"):
        dr.render_depth(verts, np.array([[0, 1, 3]]), intr)


def test_chunking_gives_identical_images(monkeypatch):
    intr = camera.preset("kinect_v1", (160, 120))
    unit, faces = _icosphere(3)
    verts = unit * [0.4, 0.8, 0.3] + [0, 0, 2.0]
    full = dr.render_depth(verts, faces, intr)
    monkeypatch.setattr(dr, "CHUNK", 997)
    small = dr.render_depth(verts, faces, intr)
    assert np.array_equal(full[0], small[0]) and np.array_equal(full[1], small[1])
