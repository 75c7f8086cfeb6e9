"""Point-to-surface distances (vertex, edge and face regions; exact pruning) and the error statistics."""
import numpy as np
import pytest

from articula.solver.geometry.surface_distance import (closest_points_on_triangles, distance_to_surface,
                                              error_statistics, per_vertex_scan_distances)

A, B, C = np.array([0.0, 0, 0]), np.array([2.0, 0, 0]), np.array([0.0, 2, 0])


@pytest.mark.parametrize("p, expected", [
    ((0.5, 0.5, 3.0), (0.5, 0.5, 0.0)),      # face region: straight down
    ((-1.0, -1.0, 1.0), (0.0, 0.0, 0.0)),    # vertex A
    ((3.0, -0.5, 0.0), (2.0, 0.0, 0.0)),     # vertex B
    ((-0.5, 3.0, 0.0), (0.0, 2.0, 0.0)),     # vertex C
    ((1.0, -2.0, 0.5), (1.0, 0.0, 0.0)),     # edge AB
    ((-2.0, 1.0, 0.0), (0.0, 1.0, 0.0)),     # edge AC
    ((2.0, 2.0, 1.0), (1.0, 1.0, 0.0)),      # edge BC
])
def test_closest_point_regions(p, expected):
    q = closest_points_on_triangles(np.array([p]), A[None], B[None], C[None])
    np.testing.assert_allclose(q[0], expected, atol=1e-12)


def test_degenerate_triangle_uses_its_edges():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[2.0, 0, 0]])   # collinear
    q = closest_points_on_triangles(np.array([[1.5, 1.0, 0.0]]), a, b, c)
    np.testing.assert_allclose(q[0], [1.5, 0, 0], atol=1e-12)


def _sampled_distance(points, vertices, faces, n=60):
    """Reference: minimum over a dense barycentric sampling of every triangle (an upper bound that is
    within the sampling spacing of the true distance)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    tri = vertices[faces]
    samples = (tri[:, 0, None] * (1 - u - v)[:, None] + tri[:, 1, None] * u[:, None]
               + tri[:, 2, None] * v[:, None]).reshape(-1, 3)
    from scipy.spatial import cKDTree
    return cKDTree(samples).query(points)[0]


def test_distance_to_surface_matches_dense_sampling_and_never_exceeds_it():
    rng = np.random.default_rng(3)
    vertices = rng.normal(size=(30, 3))
    faces = rng.integers(0, 30, size=(40, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    points = rng.normal(size=(200, 3)) * 1.5
    d = distance_to_surface(points, vertices, faces)
    ref = _sampled_distance(points, vertices, faces)
    assert np.all(d <= ref + 1e-9)                      # exact distance is never above a sampled one
    np.testing.assert_allclose(d, ref, atol=0.05)        # and close to it (sampling spacing)
    # brute force over all triangles with the same closest-point routine: pruning loses nothing
    P = np.repeat(points, len(faces), axis=0)
    T = vertices[np.tile(faces, (len(points), 1))]
    brute = np.linalg.norm(closest_points_on_triangles(P, T[:, 0], T[:, 1], T[:, 2]) - P, axis=1)
    np.testing.assert_allclose(d, brute.reshape(len(points), -1).min(axis=1), atol=1e-12)


def test_per_vertex_scan_distances_of_an_offset_plane():
    g = np.stack(np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 6), indexing="ij"), -1).reshape(-1, 2)
    verts = np.column_stack([g, np.zeros(len(g))])
    idx = np.arange(36).reshape(6, 6)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    scans = np.stack([verts, verts + [0, 0, 0.5]])
    posed = np.stack([verts + [0, 0, 0.01], verts + [0.3, 0.1, 0.5 - 0.02]])   # in-plane slide costs nothing
    dist = per_vertex_scan_distances(posed, scans, faces)
    # frame 1: points that slid off the plane's edges (x > 1 or y > 1) are farther than 0.02
    inside = (posed[1, :, 0] <= 1.0) & (posed[1, :, 1] <= 1.0)
    np.testing.assert_allclose(dist[0], 0.01, atol=1e-12)
    np.testing.assert_allclose(dist[1, inside], 0.02, atol=1e-12)
    assert np.all(dist[1, ~inside] > 0.02)


def test_error_statistics_as_the_spec_defines_them():
    s = error_statistics([1, 2, 3, 4, 100])
    assert s["median"] == 3 and s["mad"] == 1 and s["max"] == 100 and s["count"] == 5
    assert s["iqr"] == pytest.approx(52 - 1.5)           # Q1 = median(1, 2), Q3 = median(4, 100)
    assert s["mean"] == pytest.approx(22.0) and s["std"] == pytest.approx(np.std([1, 2, 3, 4, 100]))
    assert error_statistics([[2.0, 4.0], [6.0, 8.0]])["iqr"] == pytest.approx(7 - 3)


def _brute_force(points, verts, faces):
    """Minimum over all triangles of the region-test closest-point distance ``(N,)``."""
    P = np.repeat(points, len(faces), axis=0)
    T = verts[np.tile(faces, (len(points), 1))]
    d = np.linalg.norm(closest_points_on_triangles(P, T[:, 0], T[:, 1], T[:, 2]) - P, axis=1)
    return d.reshape(len(points), -1).min(axis=1)


@pytest.mark.parametrize("seed", [7, 8, 9])
def test_distance_to_surface_equals_brute_force_on_mixed_triangle_sizes(seed):
    """Tiny and huge triangles (several radius groups) and points at several distances (several bound
    groups): the pruned distance equals the brute-force minimum over all triangles."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 9), np.linspace(0, 1, 9), indexing="ij"), -1).reshape(-1, 2)
    g = g ** 3                                              # cells from 0.002 to 0.3 wide
    verts = np.column_stack([g, 0.05 * rng.normal(size=len(g))])
    idx = np.arange(81).reshape(9, 9)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    points = rng.uniform(-0.2, 1.2, size=(400, 3)) * [1, 1, 0.3]
    dist = distance_to_surface(points, verts, faces)
    np.testing.assert_allclose(dist, _brute_force(points, verts, faces), rtol=1e-12, atol=0)


def _sliver_mesh(rng):
    """A fan of long thin triangles (aspect up to 1e4), needles, one collinear (flat) triangle, a few
    big and many tiny triangles, scattered in a 1 m box."""
    tris = []
    for _ in range(60):                                    # slivers: long edge 0.2-1, width 1e-4-1e-2
        a = rng.uniform(0, 1, 3)
        along = rng.normal(size=3)
        along *= rng.uniform(0.2, 1.0) / np.linalg.norm(along)
        side = np.cross(along, rng.normal(size=3))
        side *= 10.0 ** rng.uniform(-4, -2) / np.linalg.norm(side)
        tris.append([a, a + along, a + rng.uniform(0.2, 0.8) * along + side])
    for _ in range(4):                                     # big
        tris.append(rng.uniform(0, 1, (3, 3)))
    for _ in range(200):                                   # tiny
        tris.append(rng.uniform(0, 1, 3) + 1e-3 * rng.normal(size=(3, 3)))
    a = rng.uniform(0, 1, 3)
    tris.append([a, a + [0.1, 0.2, 0.0], a + [0.2, 0.4, 0.0]])        # flat: collinear
    verts = np.asarray(tris, float).reshape(-1, 3)
    return verts, np.arange(len(verts)).reshape(-1, 3)


@pytest.mark.parametrize("seed", [0, 1])
def test_distance_to_surface_exact_on_long_thin_and_flat_triangles(seed):
    """Slivers, needles, a flat triangle and mixed sizes, points near the surface and far away: equal to
    the brute-force minimum (same closest-point definition) to rounding."""
    rng = np.random.default_rng(seed)
    verts, faces = _sliver_mesh(rng)
    near = verts[rng.integers(0, len(verts), 300)] + 10.0 ** rng.uniform(-6, -1, (300, 1)) * rng.normal(size=(300, 3))
    far = rng.uniform(-3, 4, size=(60, 3))
    points = np.concatenate([near, far, verts[:5]])          # and points exactly on vertices
    dist = distance_to_surface(points, verts, faces)
    np.testing.assert_allclose(dist, _brute_force(points, verts, faces), rtol=1e-9, atol=1e-15)
    assert np.all(dist[-5:] == 0.0)


@pytest.mark.parametrize("setting", [("CHUNK_PAIRS", 50), ("FAR", 0.0)])
def test_distance_to_surface_pruning_loses_nothing_in_the_other_paths(monkeypatch, setting):
    """With a tiny pair budget every search runs in chunks of rows; with FAR = 0 every point group uses
    per-point ball queries: same result as brute force."""
    import articula.solver.geometry.surface_distance as sd
    monkeypatch.setattr(sd, *setting)
    rng = np.random.default_rng(4)
    verts, faces = _sliver_mesh(rng)
    points = rng.uniform(-1, 2, size=(150, 3))
    np.testing.assert_allclose(sd.distance_to_surface(points, verts, faces), _brute_force(points, verts, faces),
                               rtol=1e-9, atol=1e-15)


def test_pair_kernel_matches_the_region_test():
    """The frame-based pair distance equals |p − closest_points_on_triangles| (random and thin
    triangles, points in all Voronoi regions) to rounding."""
    from articula.solver.geometry.surface_distance import _pair_distances, _triangle_frames
    rng = np.random.default_rng(5)
    tri = rng.normal(size=(2000, 3, 3))
    tri[:500, 2] = tri[:500, 0] + 0.5 * (tri[:500, 1] - tri[:500, 0]) + 1e-5 * rng.normal(size=(500, 3))
    points = rng.normal(size=(2000, 3)) * 2
    idx = np.arange(2000)
    d = _pair_distances(points, tri, _triangle_frames(tri), idx, idx)
    ref = np.linalg.norm(closest_points_on_triangles(points, tri[:, 0], tri[:, 1], tri[:, 2]) - points, axis=1)
    np.testing.assert_allclose(d, ref, rtol=1e-10, atol=1e-14)


def test_distance_to_surface_of_no_points_and_no_triangles():
    verts = np.eye(3)
    assert distance_to_surface(np.zeros((0, 3)), verts, [[0, 1, 2]]).shape == (0,)
    with pytest.raises(ValueError):
        distance_to_surface(np.zeros((2, 3)), verts, np.zeros((0, 3), int))


def test_frames_measured_side_by_side_equal_frame_by_frame():
    """Small frames are measured in batches laid side by side; every distance equals brute force over
    the frame's own triangles, also for points far off the surface (other frames' triangles never
    count)."""
    from articula.solver.geometry import surface_distance as sd
    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5), indexing="ij"), -1).reshape(-1, 2)
    verts = np.column_stack([g, 0.2 * np.sin(3 * g[:, 0])])
    idx = np.arange(25).reshape(5, 5)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    M = 300                                                          # 25 points a frame: batches of 800
    surfaces = verts[None] + rng.normal(scale=0.05, size=(M, 25, 3)) + rng.normal(scale=2.0, size=(M, 1, 3))
    points = surfaces + rng.normal(scale=0.02, size=surfaces.shape)
    points[::7, 3] += [0.0, 0.0, 5.0]                                 # far from the surface
    dist = sd.per_vertex_scan_distances(points, surfaces, faces)
    assert sd.BATCH_POINTS // 25 > 1
    T = surfaces[:, faces]                                             # (M, F, 3, 3)
    for m in (0, 1, 7, 150, 299):
        P = np.repeat(points[m], len(faces), axis=0)
        Tm = np.tile(T[m], (25, 1, 1))
        brute = np.linalg.norm(closest_points_on_triangles(P, Tm[:, 0], Tm[:, 1], Tm[:, 2]) - P, axis=1)
        np.testing.assert_allclose(dist[m], brute.reshape(25, -1).min(axis=1), rtol=0, atol=1e-11)
