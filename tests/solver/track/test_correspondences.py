"""Correspondences (model-adaptive mocap dissertation §4.1.2): the normal-checked nearest neighbour against
brute force, variant (B) trimming against a sequential walk, two-way pairs of identical meshes."""
import numpy as np
import pytest
import trimesh

from articula.solver.track import correspondences as corr
from articula.solver.geometry.normals import vertex_normals


def _unit(x):
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _brute_nearest_compatible(points, pn, queries, qn, k):
    out = []
    for q, n in zip(queries, qn):
        order = np.argsort(np.linalg.norm(points - q, axis=1), kind="stable")[:k]
        ok = [i for i in order if pn[i] @ n > 0]
        out.append(ok[0] if ok else -1)
    return np.array(out)


@pytest.mark.parametrize("k", [1, 4, 16])
def test_nearest_compatible_matches_brute_force(k):
    rng = np.random.default_rng(k)
    pts, qs = rng.random((300, 3)), rng.random((200, 3))
    pn, qn = _unit(rng.normal(size=(300, 3))), _unit(rng.normal(size=(200, 3)))
    got = corr.nearest_compatible(pts, pn, qs, qn, k)
    np.testing.assert_array_equal(got, _brute_nearest_compatible(pts, pn, qs, qn, k))
    if k == 1:
        assert (got == -1).any()          # about half of the nearest points face away
    hit = got >= 0
    assert (np.einsum("ij,ij->i", pn[got[hit]], qn[hit]) > 0).all()


def _sequential_trim(d, tris):
    removed = np.zeros(len(d), bool)
    for t in tris:
        present = [v for v in t if not np.isnan(d[v])]
        if not present or removed[list(t)].any():
            continue
        removed[max(present, key=lambda v: (d[v], -list(t).index(v)))] = True
    return removed


def test_trim_hand_made_strip():
    tris = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]])
    removed, _ = corr.trim_per_triangle(np.array([1.0, 5.0, 2.0, 3.0, 0.5, 0.1]), tris)
    # t0 removes 1; t1 holds 1 (skipped); t2 = (2, 3, 4) removes 3; t3 holds 3 (skipped)
    assert set(np.flatnonzero(removed)) == {1, 3}
    removed, _ = corr.trim_per_triangle(np.array([5.0, 1.0, 2.0, 3.0, 0.5, 4.0]), tris)
    # t0 removes 0; t1 = (1, 3, 2) removes 3; t2 and t3 hold 3
    assert set(np.flatnonzero(removed)) == {0, 3}
    removed, _ = corr.trim_per_triangle(np.array([5.0, np.nan, 2.0, np.nan, np.nan, 4.0]), tris)
    # NaN = no pair: t1 = (1, 3, 2) has only vertex 2 -> removed; t3 = (3, 5, 4) removes 5
    assert set(np.flatnonzero(removed)) == {0, 2, 5}


@pytest.mark.parametrize("smooth", [False, True])
def test_trim_equals_sequential_walk_on_grid(smooth):
    grid = trimesh.creation.box().subdivide().subdivide().subdivide()
    rng = np.random.default_rng(3)
    tris = np.asarray(grid.faces)[rng.permutation(len(grid.faces))]
    v = np.asarray(grid.vertices)
    d = (v[:, 0] + 0.3 * v[:, 1]) if smooth else rng.random(len(v))
    d[rng.random(len(v)) < 0.05] = np.nan
    removed, rounds = corr.trim_per_triangle(d, tris)
    np.testing.assert_array_equal(removed, _sequential_trim(d, tris))
    assert rounds >= 1 and 0.2 < removed.mean() < 0.8
    # every triangle with a pair holds a removed one (variant B's invariant)
    has_pair = ~np.isnan(d[tris]).all(axis=1)
    assert removed[tris[has_pair]].any(axis=1).all()


def test_identical_meshes_pair_at_zero_distance_both_ways():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    n = vertex_normals(v, f)
    out = corr.correspondences(v, f, n, v, n, f, options=corr.CorrespondenceOptions(trim=False))
    assert out.from_capture.sum() == len(v) and (~out.from_capture).sum() == len(v)
    np.testing.assert_allclose(out.distances, 0.0, atol=1e-12)
    np.testing.assert_allclose(out.model_points(v), out.targets, atol=1e-12)
    np.testing.assert_allclose(out.weights.sum(axis=1), 1.0)


def test_thin_plate_does_not_match_across_sides():
    top = trimesh.creation.box(extents=(1.0, 1.0, 0.002))
    v, f = np.asarray(top.vertices), np.asarray(top.faces)
    n = vertex_normals(v, f)
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-0.4, 0.4, (200, 2)), np.full(200, -0.0012)]    # just below the lower face
    normals = np.tile([0.0, 0.0, 1.0], (200, 1))                              # but facing up
    out = corr.correspondences(v, f, n, pts, normals, None, options=corr.CorrespondenceOptions(trim=False))
    model_n = np.einsum("pi,pij->pj", out.weights, n[out.vertex_ids])
    assert (np.einsum("ij,ij->i", model_n, out.target_normals) > 0).all()
    assert (out.model_points(v)[:, 2] > 0).all()                             # the upper side


def test_surface_points_lie_on_the_model():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    n = vertex_normals(v, f)
    rng = np.random.default_rng(1)
    dirs = _unit(rng.normal(size=(500, 3)))
    pts = 0.3 * dirs
    out = corr.correspondences(v, f, n, pts, dirs, None, options=corr.CorrespondenceOptions(trim=False))
    cap = out.from_capture
    vertex_only = corr.correspondences(v, f, n, pts, dirs, None,
                                       options=corr.CorrespondenceOptions(trim=False, surface=False))
    assert np.median(out.distances[cap]) < 0.3 * np.median(vertex_only.distances[vertex_only.from_capture])
    # the model points lie on the triangles they name
    ids = out.vertex_ids[cap]
    assert (out.weights[cap] >= -1e-12).all()
    on_tri = np.array([sorted(r) in [sorted(t) for t in f[np.any(f == r[0], axis=1)]] or len(set(r)) == 1
                       for r in ids])
    assert on_tri.all()


def test_irls_weights_and_energy_follow_the_distances():
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    n = vertex_normals(v, f)
    rng = np.random.default_rng(2)
    pts = v * 1.0 + rng.normal(scale=0.003, size=v.shape)
    opts = corr.CorrespondenceOptions(eps=0.002)
    out = corr.correspondences(v, f, n, pts, n, f, options=opts)
    np.testing.assert_allclose(out.irls_weights, 1 / np.sqrt(out.distances ** 2 + 0.002 ** 2))
    np.testing.assert_allclose(out.energy, np.mean(np.sqrt(out.distances ** 2 + 0.002 ** 2)))
    np.testing.assert_allclose(np.linalg.norm(out.targets - out.model_points(v), axis=1), out.distances)
    assert 0.2 < out.stats["removed_capture"] < 0.8 and 0.2 < out.stats["removed_model"] < 0.8
