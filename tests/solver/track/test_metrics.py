"""Tracking metrics (solver.track.metrics): exact point-to-mesh distances against a brute-force reference
written here (plane projection inside the triangle, else the nearest of the three edge segments), the
vertex / edge / face regions of one triangle in closed form, foot points, and the dissertation's robust
statistics (T23)."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.track import metrics


def _segment(p, a, b):
    """Closest points on segments a-b (rows) to p (rows); a zero-length segment is its point."""
    ab = b - a
    L = np.einsum("ni,ni->n", ab, ab)
    t = np.clip(np.einsum("ni,ni->n", p - a, ab) / np.where(L > 0, L, 1.0), 0.0, 1.0)
    return a + t[:, None] * ab


def _brute(points, vertices, faces):
    """Distance of every point to every triangle, minimum over triangles: the foot of the perpendicular
    when it lies inside (barycentric coordinates >= 0, non-degenerate triangles), else the nearest edge."""
    out = np.full(len(points), np.inf)
    for a, b, c in vertices[faces]:
        A, B, C = (np.broadcast_to(x, points.shape) for x in (a, b, c))
        d = np.min([np.linalg.norm(_segment(points, s, e) - points, axis=1) for s, e in ((A, B), (B, C), (C, A))],
                   axis=0)
        n = np.cross(b - a, c - a)
        area2 = np.linalg.norm(n)
        if area2 > 1e-9 * max(np.dot(b - a, b - a), np.dot(c - a, c - a)):
            n = n / area2
            h = (points - a) @ n
            foot = points - h[:, None] * n
            lam = [np.cross(e - s, foot - s) @ n for s, e in ((a, b), (b, c), (c, a))]
            inside = np.all(np.array(lam) >= 0, axis=0)
            d = np.where(inside, np.abs(h), d)
        out = np.minimum(out, d)
    return out


def test_one_triangle_vertex_edge_and_face_regions():
    """Right triangle (0,0,0), (1,0,0), (0,1,0): a point above the face is its height away, a point
    beyond an edge the distance to that edge, beyond a corner the distance to the corner."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    p = np.array([[0.2, 0.3, 0.5],          # face: 0.5
                  [0.5, -0.4, 0.3],         # edge AB: sqrt(0.4² + 0.3²) = 0.5
                  [1.0, 1.0, 0.0],          # edge BC: sqrt(2)/2
                  [-0.3, 0.5, -0.4],        # edge CA: 0.5
                  [1.3, -0.4, 0.0],         # corner B: 0.5
                  [-1.0, -1.0, 1.0],        # corner A: sqrt(3)
                  [0.0, 1.6, 0.8]])         # corner C: 1.0
    want = [0.5, 0.5, np.sqrt(0.5), 0.5, 0.5, np.sqrt(3.0), 1.0]
    assert np.allclose(metrics.point_to_mesh(p, v, f), want, rtol=0, atol=1e-15)
    d, feet, tri = metrics.closest_points(p, v, f)
    assert np.allclose(feet[[0, 4, 5]], [[0.2, 0.3, 0], [1, 0, 0], [0, 0, 0]], atol=1e-15)
    assert (tri == 0).all()


@pytest.mark.parametrize("seed", range(4))
def test_random_meshes_with_degenerate_triangles_and_far_points_match_brute_force(seed):
    """Random triangle soups (sizes over two orders of magnitude, some zero-area: repeated vertices and
    collinear corners) with points near the surface, far away (100x the mesh) and on vertices."""
    rng = np.random.default_rng(seed)
    V = rng.normal(size=(60, 3))
    F = rng.integers(0, 60, (80, 3))
    V = np.concatenate([V, [[0, 0, 0], [1, 1, 1], [2, 2, 2], [5, 5, 5]]])
    F = np.concatenate([F, [[0, 0, 1], [60, 61, 62], [63, 63, 63]]])       # repeated, collinear, a point
    for k in range(3):                                                     # a corner repeated, each place
        F[10 * k:10 * k + 10, (k + 1) % 3] = F[10 * k:10 * k + 10, k]
    V[:30] *= rng.uniform(0.01, 1.0, (30, 1))
    near = V[F].mean(axis=1)[:40] + rng.normal(scale=0.05, size=(40, 3))
    far = rng.normal(size=(30, 3)) * 100.0
    P = np.concatenate([near, far, V[:10], rng.normal(size=(100, 3))])
    want = _brute(P, V, F)
    got = metrics.point_to_mesh(P, V, F)
    assert np.abs(got - want).max() <= 1e-12 * (1 + want.max())
    d, feet, tri = metrics.closest_points(P, V, F)
    assert np.array_equal(d, got)
    assert np.abs(np.linalg.norm(feet - P, axis=1) - d).max() <= 1e-12 * (1 + want.max())
    on = np.array([_brute(feet[i:i + 1], V, F[tri[i]:tri[i] + 1])[0] for i in range(len(P))])
    assert on.max() < 1e-12 * (1 + np.abs(V).max())                      # the foot lies on its triangle


def test_many_points_on_a_fine_mesh_match_brute_force_on_a_sample():
    """A 40x40 wavy sheet (3,042 triangles) and 20,000 points: exact for a random sample of 300."""
    rng = np.random.default_rng(7)
    x, y = np.meshgrid(np.linspace(0, 1, 40), np.linspace(0, 1, 40))
    V = np.stack([x.ravel(), y.ravel(), 0.05 * np.sin(6 * x.ravel()) * np.cos(5 * y.ravel())], axis=1)
    i = (np.arange(39)[:, None] * 40 + np.arange(39)[None]).ravel()
    F = np.concatenate([np.stack([i, i + 1, i + 41], 1), np.stack([i, i + 41, i + 40], 1)])
    P = rng.uniform(-0.2, 1.2, (20000, 3)) * [1, 1, 0.3]
    d = metrics.point_to_mesh(P, V, F)
    s = rng.choice(len(P), 300, replace=False)
    assert np.abs(d[s] - _brute(P[s], V, F)).max() < 1e-13


def test_robust_stats_as_the_dissertation_defines_them():
    """T23: X = {1, 2, 3, 4, 100}: MED 3, MAD 1; Q1 / Q3 = medians of the lower / upper halves without
    the middle element (1.5, 52); an even count splits in two halves."""
    s = metrics.robust_stats([100.0, 3, 1, 4, 2])
    assert s == {"mean": 22.0, "std": pytest.approx(np.std([1, 2, 3, 4, 100])), "median": 3.0, "mad": 1.0,
                 "iqr": 50.5}
    s = metrics.robust_stats(np.arange(1.0, 9.0))
    assert s["median"] == 4.5 and s["iqr"] == 6.5 - 2.5 and s["mad"] == 2.0
    assert all(np.isnan(v) for v in metrics.robust_stats([]).values())


def test_bad_input_is_refused():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    for points, vertices, faces, msg in (
            ([[0, 0, np.nan]], v, f, "points: non-finite"),
            ([[0, 0]], v, f, "points: expected shape"),
            ([[0, 0, 0]], v, [[0, 1, 3]], "faces: vertex indices"),
            ([[0, 0, 0]], v, np.zeros((0, 3), int), "faces: expected shape"),
            ([[0, 0, 0]], v, [[0.0, 1, 2]], "faces: expected integer")):
        with pytest.raises(ArticulaInputError, match=msg):
            metrics.point_to_mesh(points, vertices, faces)
    assert metrics.point_to_mesh(np.zeros((0, 3)), v, f).shape == (0,)
