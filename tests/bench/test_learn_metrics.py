"""The benchmarks' evaluation metrics (bench/_learn_metrics.py) against brute-force references."""
import itertools

import numpy as np
import pytest

from articula.bench import _learn_metrics as metrics
from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.surface_distance import closest_points_on_triangles


def brute_force_distance(points, vertices, faces):
    """Every point against every triangle."""
    P, F = len(points), len(faces)
    tri = vertices[faces]
    p = np.repeat(points, F, axis=0)
    q = closest_points_on_triangles(p, np.tile(tri[:, 0], (P, 1)), np.tile(tri[:, 1], (P, 1)),
                                    np.tile(tri[:, 2], (P, 1)))
    return np.linalg.norm(q - p, axis=1).reshape(P, F).min(axis=1)


def bumpy_grid(n=12, seed=0):
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    v = np.stack([x, y, 0.05 * rng.normal(size=x.shape)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    return v, faces


def test_scan_to_model_matches_brute_force_in_all_regions():
    verts, faces = bumpy_grid()
    rng = np.random.default_rng(1)
    # points above faces, beyond the borders (edge regions) and beyond the corners (vertex regions)
    scan = np.concatenate([rng.uniform([0, 0, -0.3], [1, 1, 0.3], (150, 3)),
                           rng.uniform([-0.5, 0.2, -0.2], [0.0, 0.8, 0.2], (50, 3)),
                           rng.uniform([1.0, 1.0, -0.2], [1.5, 1.5, 0.2], (50, 3))])
    posed = np.stack([verts, verts + [0.1, 0.0, 0.2]])
    scans = np.stack([scan, scan])
    d = metrics.scan_to_model_distances(scans, posed, faces)
    assert d.shape == (2, 250)
    for m in range(2):
        np.testing.assert_allclose(d[m], brute_force_distance(scan, posed[m], faces), rtol=0, atol=1e-12)
    # one direction only: model vertices far from a small scan do not count
    small = scan[None, :5]
    assert metrics.scan_to_model_distances(small, posed[:1], faces).shape == (1, 5)


def test_zero_for_the_model_itself_and_surface_not_vertices():
    verts, faces = bumpy_grid()
    assert metrics.scan_to_model_distances(verts[None], verts[None], faces).max() < 1e-12
    # the centroid of every triangle lies on the surface (distance 0) but away from all vertices
    cents = verts[faces].mean(axis=1)
    assert metrics.scan_to_model_distances(cents[None], verts[None], faces).max() < 1e-12


def test_statistics_in_millimetres():
    # dissertation (model-adaptive mocap) T23, metres in
    s = metrics.statistics_mm(np.array([1.0, 2, 3, 4, 100]) / 1000)
    assert s["median"] == pytest.approx(3.0) and s["mad"] == pytest.approx(1.0)
    assert s["mean"] == pytest.approx(22.0) and s["max"] == pytest.approx(100.0)
    assert s["iqr"] == pytest.approx(52.0 - 1.5) and s["count"] == 5


@pytest.mark.parametrize("n_learned, n_ref", [(4, 6), (6, 4), (5, 5)])
def test_joint_matching_is_the_best_assignment(n_learned, n_ref):
    rng = np.random.default_rng(n_learned * 10 + n_ref)
    a, b = rng.normal(size=(n_learned, 3)), rng.normal(size=(n_ref, 3))
    match = metrics.match_joints(a, b)
    k = min(n_learned, n_ref)
    assert len(match.learned) == len(set(match.learned)) == k
    assert len(set(match.reference)) == k
    np.testing.assert_allclose(match.distances, np.linalg.norm(a[match.learned] - b[match.reference], axis=1))
    best = np.inf                                                         # every injective assignment
    if n_learned <= n_ref:
        for perm in itertools.permutations(range(n_ref), n_learned):
            best = min(best, np.linalg.norm(a - b[list(perm)], axis=1).sum())
    else:
        for perm in itertools.permutations(range(n_learned), n_ref):
            best = min(best, np.linalg.norm(a[list(perm)] - b, axis=1).sum())
    assert match.distances.sum() == pytest.approx(best, rel=1e-12)


def test_joint_matching_recovers_a_shuffled_skeleton():
    rng = np.random.default_rng(7)
    ref = rng.uniform(-1, 1, (18, 3))
    perm = rng.permutation(18)
    match = metrics.match_joints(ref[perm] + 0.001 * rng.normal(size=(18, 3)), ref)
    np.testing.assert_array_equal(match.reference, perm[match.learned])


def test_dem_bones_rmse_definition():
    rng = np.random.default_rng(3)
    y = rng.normal(size=(7, 11, 3))
    x = y + rng.normal(size=y.shape) * 0.1
    e = 0.0
    for k in range(7):                                                    # Dem Bones' loop, literally
        for i in range(11):
            e += float(np.sum((x[k, i] - y[k, i]) ** 2))
    assert metrics.dem_bones_rmse(x, y) == pytest.approx(np.sqrt(e / 7 / 11), rel=1e-12)
    offset = np.zeros_like(y)
    offset[..., 0] = 0.3                                                  # every vertex 0.3 away
    assert metrics.dem_bones_rmse(y + offset, y) == pytest.approx(0.3)


def test_bad_input():
    verts, faces = bumpy_grid(4)
    with pytest.raises(ArticulaInputError, match="posed: 2 frames for 1 scans"):
        metrics.scan_to_model_distances(verts[None], np.stack([verts, verts]), faces)
    with pytest.raises(ArticulaInputError, match="faces: indices"):
        metrics.scan_to_model_distances(verts[None], verts[None], faces + 100)
    bad = verts.copy()
    bad[3, 1] = np.inf
    with pytest.raises(ArticulaInputError, match=r"scans: non-finite value at index \(0, 3, 1\)"):
        metrics.scan_to_model_distances(bad[None], verts[None], faces)
    with pytest.raises(ArticulaInputError, match="reconstructed: shape"):
        metrics.dem_bones_rmse(np.zeros((2, 3, 3)), np.zeros((2, 4, 3)))
    with pytest.raises(ArticulaInputError, match="learned: expected shape"):
        metrics.match_joints(np.zeros((3, 2)), np.zeros((3, 3)))


def test_joint_matching_of_trajectories_uses_the_mean_distance_over_frames():
    rng = np.random.default_rng(9)
    ref = rng.normal(size=(6, 5, 3))                                      # 6 frames, 5 joints
    perm = np.array([3, 0, 4, 1])
    learned = ref[:, perm] + 0.01 * rng.normal(size=(6, 4, 3))
    match = metrics.match_joints(learned, ref)
    np.testing.assert_array_equal(match.reference, perm[match.learned])
    expect = np.linalg.norm(learned[:, match.learned] - ref[:, match.reference], axis=2).mean(axis=0)
    np.testing.assert_allclose(match.distances, expect)
    best = min(np.linalg.norm(learned - ref[:, list(p)], axis=2).mean(axis=0).sum()     # brute force
               for p in itertools.permutations(range(5), 4))
    assert match.distances.sum() == pytest.approx(best, rel=1e-12)
    with pytest.raises(ArticulaInputError, match="reference: 5 frames for 6"):
        metrics.match_joints(learned, ref[:5])


def test_posed_joints_follow_the_chain():
    from articula.sample_scenes import synthetic
    from articula.solver.rig.kinematics import forward_kinematics
    sk = synthetic.human_skeleton()
    poses = synthetic.random_poses(3, sk.num_bones, seed=2)
    p = metrics.posed_joints(sk, poses)
    Rm, tm = forward_kinematics(sk, poses)
    for b in range(1, sk.num_bones):                                      # carried by the parent part too
        parent = sk.parents[b]
        np.testing.assert_allclose(p[:, b], np.einsum("nij,j->ni", Rm[:, parent], sk.heads[b]) + tm[:, parent],
                                   atol=1e-12)
