"""Gaussian-mixture maths of the pose prior (solver.tracking.gmm) against closed forms and planted mixtures."""
import numpy as np
import pytest

from articula.solver.tracking import gmm


def _clusters(counts, centres, sd, seed=0):
    rng = np.random.default_rng(seed)
    return np.concatenate([c + sd * rng.standard_normal((n, len(c))) for n, c in zip(counts, centres)])


def test_one_component_is_sample_mean_and_covariance():
    X = np.random.default_rng(1).standard_normal((40, 6)) @ np.diag([1, 2, 0.5, 0.1, 1, 3]) + 0.7
    mix = gmm.fit(X, 1)
    reg = gmm.regularisation(X)
    np.testing.assert_allclose(mix.weights, [1.0])
    np.testing.assert_allclose(mix.means[0], X.mean(axis=0), atol=1e-12)
    cov = (X - X.mean(axis=0)).T @ (X - X.mean(axis=0)) / len(X) + reg * np.eye(6)
    np.testing.assert_allclose(np.linalg.inv(mix.precisions[0]), cov, rtol=1e-10, atol=1e-12)


def test_log_likelihood_is_the_gaussian_density():
    X = np.random.default_rng(2).standard_normal((30, 6))
    mix = gmm.fit(X, 1)
    cov = np.linalg.inv(mix.precisions[0])
    d = X - mix.means[0]
    ref = -0.5 * (np.einsum("ni,ij,nj->n", d, mix.precisions[0], d) + np.log(np.linalg.det(2 * np.pi * cov)))
    np.testing.assert_allclose(gmm.log_likelihood(X, mix), ref, rtol=1e-10)


def test_em_monotone_weights_and_positive_definite():
    X = _clusters([20, 25, 15], [np.zeros(6), np.full(6, 1.0), np.r_[2.0, -1, 0, 0, 1, 0]], 0.3)
    start = gmm.fit(X, 3, max_iter=1)
    mix, history = gmm.em(X, start, reg=1e-10)
    assert np.all(np.diff(history) > -1e-9)
    assert abs(mix.weights.sum() - 1.0) < 1e-12
    assert gmm.is_positive_definite(mix.precisions)


def test_few_points_never_singular():
    X = np.tile(np.r_[0.1, 0.2, 0.3, 0.0, 0.0, 0.0], (4, 1))       # identical poses: zero covariance
    mix = gmm.fit(X, 2)
    assert gmm.is_positive_definite(mix.precisions) and np.isfinite(gmm.log_likelihood(X, mix)).all()


def test_kmeans_pp_is_seeded():
    X = np.random.default_rng(3).standard_normal((50, 6))
    a = gmm.kmeans_pp(X, 4, np.random.default_rng(7))
    b = gmm.kmeans_pp(X, 4, np.random.default_rng(7))
    assert a.shape == (4, 6) and np.array_equal(a, b)


@pytest.mark.parametrize("true_k", [1, 2, 3])
def test_loo_picks_true_component_count(true_k):
    centres = [np.zeros(6), np.r_[3.0, 0, 0, 0, 3, 0], np.r_[0.0, -3, 3, 0, 0, 0]][:true_k]
    X = _clusters([14] * true_k, centres, 0.1, seed=true_k)
    k, mix, fits, scores = gmm.select_components(X, 5)
    assert k == true_k, scores
    assert len(fits) == len(X) and scores.shape == (5,)


def test_loo_fits_never_see_their_held_out_row():
    X = _clusters([10, 10], [np.zeros(6), np.full(6, 2.0)], 0.2)
    full = gmm.fit(X, 2)
    fits = gmm.loo_fits(X, full, gmm.regularisation(X))
    keep = np.arange(1, len(X))
    ref = gmm.em(X[keep], full, gmm.regularisation(X), 50)[0]
    np.testing.assert_allclose(fits[0].means, ref.means)


def test_zeroing_keeps_positive_definite():
    C = np.eye(6)
    C[0, 3] = C[3, 0] = 0.9
    P = np.linalg.inv(C)
    assert gmm.apply_zeros(P, [(0, 3)])[0, 3] == 0.0          # zeroing keeps PD: exact zero
    Q = np.eye(6)
    for i, j in ((0, 3), (0, 4), (3, 4)):
        Q[i, j] = Q[j, i] = 0.9                                 # PD (eigenvalues 2.8, 0.1, 0.1, 1 ...)
    zeroed = Q.copy()
    zeroed[0, 3] = zeroed[3, 0] = 0.0
    assert gmm.is_positive_definite(Q) and not gmm.is_positive_definite(zeroed)
    R = gmm.apply_zeros(Q, [(0, 3)])                            # shrunk only as far as PD allows
    assert gmm.is_positive_definite(R) and 0 < R[0, 3] < 0.9 and R[0, 3] == R[3, 0]
    assert np.linalg.eigvalsh(R).min() < 1e-6
    off = np.ones((6, 6), dtype=bool)
    off[0, 3] = off[3, 0] = False
    np.testing.assert_array_equal(R[off], Q[off])


def test_greedy_pattern_on_independent_joints():
    rng = np.random.default_rng(5)
    X = np.concatenate([rng.standard_normal((30, 3)) * 0.3, rng.standard_normal((30, 3)) * 0.2], axis=1)
    k, mix, fits, _ = gmm.select_components(X, 2)
    cross = [(i, j) for i in range(3) for j in range(3, 6)]
    entries, base, score = gmm.greedy_zero_pattern(X, fits, cross)
    assert score >= base and len(entries) > 0
    sparse = gmm.sparsified(mix, entries)
    assert gmm.is_positive_definite(sparse.precisions)
    for i, j in entries:
        assert np.all(np.abs(sparse.precisions[:, i, j]) <= np.abs(mix.precisions[:, i, j]))
