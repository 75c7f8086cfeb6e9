"""Gaussian mixtures for the pose prior: EM with k-means++ start, leave-one-out model selection, and
sparsification of a precision block that keeps positive definiteness.

Dissertation (model-adaptive mocap) §4.1.1, Eq. 4.1: one mixture per pair of successive joints, learned
by EM initialised with k-means++; the component count and the zero pattern of the off-diagonal
precision entries are chosen by leave-one-out cross-validation of the held-out likelihood.  The score is
the mean held-out *log*-likelihood (the log of the geometric mean of the held-out likelihoods): the
arithmetic mean of densities rewards splitting clusters into tight components (it chose 4-5 components
for 5 of 9 planted 1-3-cluster sets, the log score chose the planted count in all 9; docs/track.md).

Shapes: samples ``X (N, D)``; a mixture holds ``weights (K,)`` (sum 1), ``means (K, D)`` and
``precisions (K, D, D)`` (inverse covariances, symmetric positive definite).  Covariances get
``reg = floor + REG_REL * mean variance of X`` (floor = ``REG_ABS`` unless given) added to their diagonal,
so a component with fewer points than dimensions (or identical points) never becomes singular.
"""
from dataclasses import dataclass

import numpy as np

REG_ABS = 1e-4          # rad²: absolute covariance floor (about 0.6° standard deviation)
REG_REL = 1e-3          # relative to the mean per-dimension variance of the data
PD_MIN_EIG = 1e-9       # smallest precision eigenvalue accepted as positive definite


@dataclass
class Mixture:
    """weights (K,), means (K, D), precisions (K, D, D)."""
    weights: np.ndarray
    means: np.ndarray
    precisions: np.ndarray

    @property
    def num_components(self) -> int:
        return len(self.weights)


def regularisation(X, floor: float = REG_ABS) -> float:
    """Covariance diagonal load for samples ``X (N, D)`` (see the module docstring)."""
    var = X.var(axis=0).mean() if len(X) > 1 else 0.0
    return floor + REG_REL * var


def kmeans_pp(X, K, rng) -> np.ndarray:
    """``K`` initial centres ``(K, D)`` chosen from ``X (N, D)`` by k-means++ (each next centre drawn with
    probability proportional to the squared distance to the nearest chosen one; Arthur and Vassilvitskii)."""
    centres = [X[rng.integers(len(X))]]
    d2 = np.sum((X - centres[0]) ** 2, axis=1)
    for _ in range(1, K):
        total = d2.sum()
        i = rng.choice(len(X), p=d2 / total) if total > 0 else rng.integers(len(X))
        centres.append(X[i])
        d2 = np.minimum(d2, np.sum((X - X[i]) ** 2, axis=1))
    return np.array(centres)


def log_components(X, mix: Mixture) -> np.ndarray:
    """``(N, K)`` log of ``weight_k * N(x_n | mean_k, precision_k^-1)`` (normalised Gaussians)."""
    return _log_components(X, mix.weights[None], mix.means[None], mix.precisions[None])[0]


def _log_components(X, weights, means, precisions) -> np.ndarray:
    """``(F, N, K)``: :func:`log_components` of ``F`` mixtures stacked as ``weights (F, K)``, ``means
    (F, K, D)``, ``precisions (F, K, D, D)`` at the same samples ``X (N, D)``."""
    D = X.shape[1]
    diff = X[None, :, None, :] - means[:, None]
    maha = np.einsum("fnki,fkij,fnkj->fnk", diff, precisions, diff)
    _, logdet = np.linalg.slogdet(precisions)
    with np.errstate(divide="ignore"):
        logw = np.log(weights)
    return (logw + 0.5 * logdet - 0.5 * D * np.log(2 * np.pi))[:, None, :] - 0.5 * maha


def log_likelihood(X, mix: Mixture) -> np.ndarray:
    """``(N,)`` log density of the (normalised) mixture at ``X (N, D)``."""
    return _logsumexp(log_components(X, mix))


def _logsumexp(lc):
    m = lc.max(axis=-1, keepdims=True)
    return (m + np.log(np.exp(lc - m).sum(axis=-1, keepdims=True)))[..., 0]


def _m_step(X, resp, reg, rows):
    """Weights ``(F, K)``, means ``(F, K, D)``, precisions ``(F, K, D, D)`` from responsibilities ``resp
    (F, N, K)`` (zero on the rows a mixture leaves out) and ``rows (F, N)``, the rows each mixture sees;
    empty components keep a tiny weight, the mean and the regularised covariance of those rows."""
    D = X.shape[1]
    nk = resp.sum(axis=1)
    safe = np.maximum(nk, 1e-12)
    means = np.einsum("fnk,nd->fkd", resp, X) / safe[..., None]
    diff = X[None, :, None, :] - means[:, None]
    cov = np.einsum("fnk,fnki,fnkj->fkij", resp, diff, diff) / safe[..., None, None]
    empty = nk < 1e-9
    if empty.any():
        f = np.nonzero(empty)[0]
        count = rows[f].sum(axis=1)[:, None]
        centre = rows[f].astype(float) @ X / count
        d = (X[None] - centre[:, None]) * rows[f][..., None]
        means[empty] = centre
        cov[empty] = np.einsum("fni,fnj->fij", d, d) / count[..., None]
    cov += reg * np.eye(D)
    weights = np.maximum(nk, 1e-12) / np.maximum(nk.sum(axis=1, keepdims=True), 1e-300)
    return weights / weights.sum(axis=1, keepdims=True), means, np.linalg.inv(cov)


def em(X, start: Mixture, reg: float, max_iter: int = 200, tol: float = 1e-8):
    """EM iterations from ``start`` on ``X (N, D)``: ``(mixture, log-likelihood history (T,))``, stopping
    when the mean log-likelihood gains less than ``tol``.  With a negligible ``reg`` this is exact EM and
    the history is non-decreasing; the covariance load can make it dip by amounts of the order of ``reg``."""
    fits, history = _em(X, np.ones((1, len(X)), dtype=bool), start, reg, max_iter, tol)
    return fits[0], history[0]


def _em(X, rows, start: Mixture, reg: float, max_iter: int, tol: float = 1e-8):
    """EM of ``F`` mixtures at once, mixture f on the rows ``rows[f] (F, N)`` of ``X``, all from
    ``start``, each stopping on its own (:func:`em`): ``(F mixtures, F histories)``."""
    F = len(rows)
    w = np.repeat(start.weights[None], F, axis=0)
    m = np.repeat(start.means[None], F, axis=0)
    L = np.repeat(start.precisions[None], F, axis=0)
    count = rows.sum(axis=1)
    history = [[] for _ in range(F)]
    active = np.arange(F)
    for _ in range(max_iter):
        lc = _log_components(X, w[active], m[active], L[active])
        ll = _logsumexp(lc)
        mean = np.where(rows[active], ll, 0.0).sum(axis=1) / count[active]
        go = np.ones(len(active), dtype=bool)
        for i, f in enumerate(active):
            history[f].append(mean[i])
            go[i] = len(history[f]) < 2 or history[f][-1] - history[f][-2] >= tol
        if not go.any():
            break
        active, lc, ll = active[go], lc[go], ll[go]
        resp = np.exp(lc - ll[..., None]) * rows[active][..., None]
        w[active], m[active], L[active] = _m_step(X, resp, reg, rows[active])
    return [Mixture(w[f], m[f], L[f]) for f in range(F)], [np.array(h) for h in history]


def fit(X, K: int, seed: int = 0, reg: float = None, max_iter: int = 200) -> Mixture:
    """A ``K``-component mixture fitted to ``X (N, D)`` by EM from a seeded k-means++ start (hard
    assignment to the nearest centre gives the first responsibilities)."""
    X = np.asarray(X, dtype=np.float64)
    reg = regularisation(X) if reg is None else reg
    centres = kmeans_pp(X, K, np.random.default_rng(seed))
    nearest = np.argmin(np.sum((X[:, None, :] - centres[None]) ** 2, axis=2), axis=1)
    resp = np.zeros((1, len(X), K))
    resp[0, np.arange(len(X)), nearest] = 1.0
    w, m, L = _m_step(X, resp, reg, np.ones((1, len(X)), dtype=bool))
    return em(X, Mixture(w[0], m[0], L[0]), reg, max_iter)[0]


def loo_fits(X, full: Mixture, reg: float, max_iter: int = 50) -> list:
    """Leave-one-out mixtures: for each n, EM on ``X`` without row n, started from ``full`` (the fit on
    all rows; a warm start, so each refit needs few iterations)."""
    return _em(X, ~np.eye(len(X), dtype=bool), full, reg, max_iter)[0]


def loo_score(X, fits: list) -> float:
    """Mean held-out log-likelihood of the rows of ``X`` under their leave-one-out fits."""
    return _held_out(X, *_stacked(fits))


def _stacked(fits: list):
    """``(weights (F, K), means (F, K, D), precisions (F, K, D, D))`` of mixtures with one component count."""
    return (np.array([f.weights for f in fits]), np.array([f.means for f in fits]),
            np.array([f.precisions for f in fits]))


def _held_out(X, weights, means, precisions) -> float:
    """Mean over n of the log density of row n of ``X (N, D)`` under stacked mixture n (the diagonal of
    every mixture at every row: N x N x K small Gaussians, cheap at the pose prior's sizes)."""
    n = np.arange(len(X))
    return float(np.mean(_logsumexp(_log_components(X, weights, means, precisions)[n, n])))


def select_components(X, k_max: int, seed: int = 0, floor: float = REG_ABS):
    """Choose the component count in 1..k_max by leave-one-out cross-validation.

    Returns ``(K, mixture fitted on all of X, its leave-one-out fits, scores (k_max,))``; ``scores[k-1]``
    is the mean held-out log-likelihood with k components (:func:`loo_score`); ties go to the smaller K."""
    X = np.asarray(X, dtype=np.float64)
    reg = regularisation(X, floor)
    k_max = max(1, min(int(k_max), len(X) - 1))
    best, scores = None, []
    for K in range(1, k_max + 1):
        full = fit(X, K, seed, reg)
        fits = loo_fits(X, full, reg)
        scores.append(loo_score(X, fits))
        if best is None or scores[-1] > best[3]:
            best = (K, full, fits, scores[-1])
    return best[0], best[1], best[2], np.array(scores)


def is_positive_definite(P) -> bool:
    """True when the symmetric matrices ``P (..., D, D)`` all have eigenvalues above ``PD_MIN_EIG``."""
    return bool(np.all(_positive_definite(P)))


def _positive_definite(P) -> np.ndarray:
    """``(...)`` per matrix of ``P (..., D, D)``: eigenvalues all above ``PD_MIN_EIG``."""
    return np.linalg.eigvalsh(P).min(axis=-1) > PD_MIN_EIG


def apply_zeros(P, entries):
    """Precision ``P (..., D, D)`` (one or a stack) with the symmetric ``entries`` [(i, j), ...] set to
    zero; a matrix that would lose positive definiteness gets those entries shrunk towards zero only as
    far as it stays positive definite (bisection on a common factor, per matrix; the originals are
    positive definite)."""
    if not entries:
        return P
    mask = np.zeros(P.shape[-2:], dtype=bool)
    for i, j in entries:
        mask[i, j] = mask[j, i] = True
    stack = P.reshape((-1,) + P.shape[-2:])
    factor = np.zeros(len(stack))
    bad = np.flatnonzero(~_positive_definite(np.where(mask, 0.0, stack)))
    if len(bad):
        lo, hi = np.zeros(len(bad)), np.ones(len(bad))          # the factor hi keeps PD, lo does not
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            ok = _positive_definite(np.where(mask, mid[:, None, None] * stack[bad], stack[bad]))
            lo, hi = np.where(ok, lo, mid), np.where(ok, mid, hi)
        factor[bad] = hi
    return np.where(mask, factor[:, None, None] * stack, stack).reshape(P.shape)


def sparsified(mix: Mixture, entries) -> Mixture:
    """The mixture with :func:`apply_zeros` applied to every component's precision."""
    return Mixture(mix.weights, mix.means, apply_zeros(mix.precisions, entries))


def greedy_zero_pattern(X, fits: list, candidates) -> tuple:
    """Greedy forward search over precision ``candidates`` [(i, j), ...] to zero: add, one at a time, the
    entry whose zeroing gives the best leave-one-out score of ``fits`` (the held-out fits of ``X``), as
    long as the score does not drop.  Returns ``(chosen entries, score without zeros, final score)``.
    The dissertation searches all patterns; a greedy search is the cheaper choice of §4.1.1's note."""
    weights, means, precisions = _stacked(fits)
    base = current = _held_out(X, weights, means, precisions)
    chosen, left = [], list(candidates)
    while left:
        trial = [(_held_out(X, weights, means, apply_zeros(precisions, chosen + [e])), e) for e in left]
        score, e = max(trial, key=lambda t: t[0])
        if score < current:
            break
        current = score
        chosen.append(e)
        left.remove(e)
    return chosen, base, current
