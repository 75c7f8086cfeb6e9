"""Limited influences of the linear-blend rig (solver.rig.influences, linear_blend.limited_weights): the
fitted weights against brute force (every k-subset of the candidates, each solved as a non-negative least
squares problem with the sum-to-one row appended, scipy.optimize.nnls) and against truncate-and-renormalise,
on random small problems, the tube body and the MakeHuman subject."""
from itertools import combinations

import numpy as np
import pytest
from scipy.optimize import nnls

from articula.sample_scenes import synthetic
from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError
from articula.solver.rig import influences
from articula.solver.rig import linear_blend as lb
from articula.solver.rig.skinning import hybrid_skin, lbs


def _problem(seed, R=40, J=9, N=6, max_m=7):
    """Random bone maps, rest points, targets near the posed points, and candidate lists of 2..max_m bones
    (vertex 0: bone 3 hits every target exactly; vertex 1: two candidates with identical maps)."""
    rng = np.random.default_rng(seed)
    Rm = np.linalg.qr(rng.normal(size=(N, J, 3, 3)))[0]
    tm = rng.normal(scale=0.1, size=(N, J, 3))
    tm[:, 8], Rm[:, 8] = tm[:, 7], Rm[:, 7]                      # bones 7 and 8 coincide
    rest = rng.normal(scale=0.3, size=(R, 3))
    targets = np.einsum("njab,rb->nrja", Rm, rest).mean(axis=2) + tm.mean(axis=1)[:, None]
    targets += rng.normal(scale=0.02, size=targets.shape)
    targets[:, 0] = np.einsum("nab,b->na", Rm[:, 3], rest[0]) + tm[:, 3]
    cand = np.full((R, max_m), -1)
    for r in range(R):
        m = rng.integers(2, max_m + 1)
        cand[r, :m] = rng.permutation(J)[:m]
    cand[0, :4] = [5, 3, 1, 0]
    cand[1, :5] = [7, 8, 2, 4, 6]
    return rest, cand, Rm, tm, targets


def _D(rest, cand_row, Rm, tm, targets_r):
    """(3N, m) residual columns p_nj - y_n of one vertex's candidates."""
    bones = cand_row[cand_row >= 0]
    p = np.einsum("njab,b->nja", Rm[:, bones], rest) + tm[:, bones]
    return (p - targets_r[:, None, :]).transpose(0, 2, 1).reshape(-1, len(bones))


def _brute_force(D, k):
    """Least cost |D w|² over every k-subset with w >= 0, Σ w = 1 (NNLS with a heavy sum-to-one row)."""
    best = np.inf
    rho = 1e4 * max(np.sqrt((D ** 2).sum()), 1e-12)
    for subset in combinations(range(D.shape[1]), min(k, D.shape[1])):
        A = np.vstack([D[:, subset], rho * np.ones((1, len(subset)))])
        b = np.zeros(len(A))
        b[-1] = rho
        w = nnls(A, b, maxiter=1000)[0]
        w /= w.sum()
        best = min(best, float(np.sum((D[:, subset] @ w) ** 2)))
    return best


@pytest.mark.parametrize("seed,k", [(0, 1), (1, 2), (2, 3), (3, 4)])
def test_best_weights_are_the_brute_force_optimum(seed, k):
    rest, cand, Rm, tm, targets = _problem(seed)
    G = np.zeros(cand.shape + cand.shape[1:])
    influences.add_gram(G, rest, cand, Rm, tm, targets)
    w = influences.best_weights(G, cand, k)
    assert np.all(w >= 0) and np.allclose(w.sum(axis=1), 1.0) and np.all((w > 0).sum(axis=1) <= k)
    assert np.all(w[cand < 0] == 0)
    for r in range(len(rest)):
        D = _D(rest[r], cand[r], Rm, tm, targets[:, r])
        got = float(np.sum((D @ w[r, cand[r] >= 0]) ** 2))
        want = _brute_force(D, k)
        assert got <= want * (1 + 1e-6) + 1e-15, (r, got, want)
        assert got >= want * (1 - 1e-4) - 1e-12, (r, got, want)     # brute force is as good
    assert np.isclose(w[0, 1], 1.0)                                  # the exact bone alone


def test_best_weights_refuse_zero_influences():
    with pytest.raises(ArticulaInputError, match="max influences"):
        influences.best_weights(np.zeros((1, 2, 2)), np.array([[0, 1]]), 0)


def test_truncate_keeps_the_largest_and_renormalises():
    W = np.array([[0.1, 0.4, 0.2, 0.3], [0.0, 0.0, 0.5, 0.5], [0.25, 0.25, 0.25, 0.25]])
    T = influences.truncate(W, 2)
    np.testing.assert_allclose(T[0], [0, 4 / 7, 0, 3 / 7])
    np.testing.assert_allclose(T[1], W[1])
    assert np.all((T > 0).sum(axis=1) <= 2) and np.allclose(T.sum(axis=1), 1.0)


def _sse(model, W, poses, segments):
    """Per-vertex Σ over poses of |LBS − hybrid|² (V,)."""
    Rm, tm = lb.bone_maps(model, poses, segments)
    return ((lbs(model.rest_vertices, W, Rm, tm) - hybrid_skin(model, poses)) ** 2).sum(axis=(0, 2))


def test_limited_weights_on_the_tube_body():
    model = synthetic.tube_body(rings=8, segments=10)
    layout, full = lb.lbs_weights(model, 3)
    fit = lb.sample_poses(model.skeleton.num_bones, lb.FIT_SEED, count=40)
    _, W = lb.limited_weights(model, 3, 4, fit)
    counts = (full > 0).sum(axis=1)
    assert counts.max() > 4                                         # the case this is about
    assert np.all((W > 0).sum(axis=1) <= 4) and np.allclose(W.sum(axis=1), 1.0, atol=1e-6) and W.min() >= 0
    np.testing.assert_array_equal(W[counts <= 4], full[counts <= 4])
    T = influences.truncate(full, 4)
    opt, trunc = _sse(model, W, fit, 3), _sse(model, T, fit, 3)
    assert np.all(opt <= trunc * (1 + 1e-5) + 1e-12)                 # per vertex, on the fitted poses
    assert opt.sum() < 0.9 * trunc.sum()
    np.testing.assert_array_equal(lb.limited_weights(model, 3, 0, fit)[1], full)
    with pytest.raises(ArticulaInputError, match="max influences"):
        lb.limited_weights(model, 3, -1, fit)


def test_limited_weights_beat_truncation_on_makehuman():
    """MakeHuman cmu_mb female (13,380 vertices, 31 bones), 4 segments, 4 influences: fitted on the
    seeded fit poses, measured there and on the held-out measuring poses (docs/RIG.md has the numbers)."""
    model = make_subject("cmu_mb", "female").hybrid_model()
    nb = model.skeleton.num_bones
    fit, held_out = lb.sample_poses(nb, lb.FIT_SEED), lb.sample_poses(nb, lb.MEASURE_SEED, count=50)
    _, full = lb.lbs_weights(model, 4)
    _, W = lb.limited_weights(model, 4, 4, fit)
    assert (full > 0).sum(axis=1).max() == 11 and (W > 0).sum(axis=1).max() == 4
    T = influences.truncate(full, 4)
    assert np.all(_sse(model, W, fit, 4) <= _sse(model, T, fit, 4) * (1 + 1e-5) + 1e-12)
    for poses in (fit, held_out):
        opt_max, opt_mean = lb.deviation(model, poses, 4, weights=W)
        tr_max, tr_mean = lb.deviation(model, poses, 4, weights=T)
        assert opt_max.max() <= tr_max.max() and opt_mean < 0.85 * tr_mean
