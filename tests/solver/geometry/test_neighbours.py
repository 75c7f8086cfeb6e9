"""Nearest-neighbour search (solver.geometry.neighbours) against brute force."""
import numpy as np

from articula.solver.geometry.neighbours import far_query_tree, nearest


def _brute_force(points, queries):
    d = np.linalg.norm(queries[:, None] - points[None], axis=2)
    return d.min(axis=1), d.argmin(axis=1)


def test_nearest_and_far_query_tree_match_brute_force():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    queries = np.concatenate([points[:50] + rng.normal(scale=1e-3, size=(50, 3)),      # near the points
                              rng.normal(scale=4.0, size=(200, 3))])                    # far from them
    dist, idx = _brute_force(points, queries)
    for got_dist, got_idx in (nearest(points, queries), far_query_tree(points).query(queries)):
        assert np.array_equal(got_idx, idx)
        assert np.allclose(got_dist, dist, rtol=0, atol=1e-12)


def test_far_query_tree_bounded_search():
    """With an upper bound, queries with no point within it get distance inf and index N."""
    rng = np.random.default_rng(1)
    points = rng.uniform(size=(300, 3))
    queries = rng.uniform(-1.0, 2.0, size=(400, 3))
    dist, idx = _brute_force(points, queries)
    got_dist, got_idx = far_query_tree(points).query(queries, distance_upper_bound=0.2)
    near = dist < 0.2
    assert near.any() and (~near).any()
    assert np.array_equal(got_idx[near], idx[near]) and np.allclose(got_dist[near], dist[near], atol=1e-12)
    assert np.all(np.isinf(got_dist[~near])) and np.all(got_idx[~near] == len(points))
