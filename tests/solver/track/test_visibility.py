"""Visibility (model-adaptive mocap dissertation §4.1.2): the depth-buffer test against brute-force ray
casting, the back side hidden from one camera, every vertex without cameras."""
import numpy as np
import trimesh

from articula.solver.depth import camera
from articula.solver.geometry.normals import vertex_normals
from articula.solver.track import visibility as vis


def _scene():
    """A sphere partly hidden behind a smaller one, seen by one camera on -Y looking at +Y."""
    back = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    front = trimesh.creation.icosphere(subdivisions=3, radius=0.12)
    v = np.concatenate([back.vertices, front.vertices + [0.1, -0.5, 0.05]])
    f = np.concatenate([back.faces, front.faces + len(back.vertices)])
    eye = np.array([0.0, -2.0, 0.0])
    return v, f, (camera.look_at(eye, [0.0, 0.0, 0.0]), camera.preset("kinect_v1", (320, 240)))


def _ray_hits(origins, ends, tri):
    """(P, T) bool: segment origin -> end crosses triangle (Moller-Trumbore, strictly between)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = b - a, c - a
    d = ends - origins
    p = np.cross(d[:, None, :], e2[None])
    det = np.einsum("ptj,tj->pt", p, e1)
    inv = 1.0 / np.where(np.abs(det) < 1e-15, np.nan, det)
    s = origins[:, None, :] - a[None]
    u = np.einsum("ptj,ptj->pt", s, p) * inv
    q = np.cross(s, e1[None])
    w = np.einsum("pj,ptj->pt", d, q) * inv
    t = np.einsum("ptj,tj->pt", q, e2) * inv
    with np.errstate(invalid="ignore"):
        return (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 1e-6) & (t < 1 - 1e-6)


def _brute_visible(v, f, n, c2w):
    eye = c2w[:3, 3]
    facing = np.einsum("ij,ij->i", n, eye - v) > 0
    out = np.zeros(len(v), bool)
    for start in range(0, len(v), 200):
        rows = np.arange(start, min(start + 200, len(v)))
        hit = _ray_hits(np.repeat(eye[None], len(rows), 0), v[rows], v[f])
        incident = (f[None, :, :] == rows[:, None, None]).any(axis=2)
        out[rows] = facing[rows] & ~(hit & ~incident).any(axis=1)
    return out


def test_depth_buffer_matches_ray_casting():
    v, f, (c2w, intr) = _scene()
    n = vertex_normals(v, f)
    got = vis.visible_vertices(v, n, f, [(c2w, intr)])
    ref = _brute_visible(v, f, n, c2w)
    assert ref.sum() > 500 and (~ref).sum() > 500
    assert (got == ref).mean() > 0.995
    # the depth-buffer depths equal the ray's hit depth on the front sphere's centre pixel
    zbuf = vis.depth_buffer(camera.world_to_camera(v, c2w), f, intr)
    centre = camera.world_to_camera(np.array([[0.1, -0.5, 0.05]]), c2w)
    uv, z = camera.project(centre, intr)
    col, row = np.rint(uv[0]).astype(int)
    assert abs(zbuf[row, col] - (z[0] - 0.12)) < 2e-3


def test_reduced_resolution_still_agrees():
    v, f, (c2w, intr) = _scene()
    n = vertex_normals(v, f)
    got = vis.visible_vertices(v, n, f, [(c2w, intr)], scale=0.5)
    assert (got == _brute_visible(v, f, n, c2w)).mean() > 0.98


def test_no_cameras_means_all_and_union_over_cameras():
    v, f, (c2w, intr) = _scene()
    n = vertex_normals(v, f)
    assert vis.visible_vertices(v, n, f, None).all()
    opposite = camera.look_at([0.0, 2.0, 0.0], [0.0, 0.0, 0.0])
    one = vis.visible_vertices(v, n, f, [(c2w, intr)])
    other = vis.visible_vertices(v, n, f, [(opposite, intr)])
    both = vis.visible_vertices(v, n, f, [(c2w, intr), (opposite, intr)])
    np.testing.assert_array_equal(both, one | other)
    assert not (one & other)[: 2562].any()     # no back-sphere vertex faces both cameras
