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
    D = X.shape[1]
    diff = X[:, None, :] - mix.means[None]
    maha = np.einsum("nki,kij,nkj->nk", diff, mix.precisions, diff)
    _, logdet = np.linalg.slogdet(mix.precisions)
    with np.errstate(divide="ignore"):
        logw = np.log(mix.weights)
    return logw + 0.5 * logdet - 0.5 * D * np.log(2 * np.pi) - 0.5 * maha


def log_likelihood(X, mix: Mixture) -> np.ndarray:
    """``(N,)`` log density of the (normalised) mixture at ``X (N, D)``."""
    lc = log_components(X, mix)
    m = lc.max(axis=1, keepdims=True)
    return (m + np.log(np.exp(lc - m).sum(axis=1, keepdims=True)))[:, 0]


def _m_step(X, resp, reg):
    """Weights, means, precisions from responsibilities ``resp (N, K)``; empty components keep a tiny
    weight, the data mean and the regularised data covariance."""
    N, D = X.shape
    nk = resp.sum(axis=0)
    safe = np.maximum(nk, 1e-12)
    means = (resp.T @ X) / safe[:, None]
    empty = nk < 1e-9
    means[empty] = X.mean(axis=0)
    diff = X[:, None, :] - means[None]
    cov = np.einsum("nk,nki,nkj->kij", resp, diff, diff) / safe[:, None, None]
    cov[empty] = np.cov(X.T, bias=True).reshape(D, D)
    cov += reg * np.eye(D)
    weights = np.maximum(nk, 1e-12) / max(nk.sum(), 1e-300)
    return Mixture(weights / weights.sum(), means, np.linalg.inv(cov))


def em(X, start: Mixture, reg: float, max_iter: int = 200, tol: float = 1e-8):
    """EM iterations from ``start`` on ``X (N, D)``: ``(mixture, log-likelihood history (T,))``, stopping
    when the mean log-likelihood gains less than ``tol``.  With a negligible ``reg`` this is exact EM and
    the history is non-decreasing; the covariance load can make it dip by amounts of the order of ``reg``."""
    mix, history = start, []
    for _ in range(max_iter):
        lc = log_components(X, mix)
        m = lc.max(axis=1, keepdims=True)
        ll = m[:, 0] + np.log(np.exp(lc - m).sum(axis=1))
        history.append(ll.mean())
        if len(history) > 1 and history[-1] - history[-2] < tol:
            break
        mix = _m_step(X, np.exp(lc - ll[:, None]), reg)
    return mix, np.array(history)


def fit(X, K: int, seed: int = 0, reg: float = None, max_iter: int = 200) -> Mixture:
    """A ``K``-component mixture fitted to ``X (N, D)`` by EM from a seeded k-means++ start (hard
    assignment to the nearest centre gives the first responsibilities)."""
    X = np.asarray(X, dtype=np.float64)
    reg = regularisation(X) if reg is None else reg
    centres = kmeans_pp(X, K, np.random.default_rng(seed))
    nearest = np.argmin(np.sum((X[:, None, :] - centres[None]) ** 2, axis=2), axis=1)
    resp = np.zeros((len(X), K))
    resp[np.arange(len(X)), nearest] = 1.0
    return em(X, _m_step(X, resp, reg), reg, max_iter)[0]


def loo_fits(X, full: Mixture, reg: float, max_iter: int = 50) -> list:
    """Leave-one-out mixtures: for each n, EM on ``X`` without row n, started from ``full`` (the fit on
    all rows; a warm start, so each refit needs few iterations)."""
    keep = ~np.eye(len(X), dtype=bool)
    return [em(X[keep[n]], full, reg, max_iter)[0] for n in range(len(X))]


def loo_score(X, fits: list) -> float:
    """Mean held-out log-likelihood of the rows of ``X`` under their leave-one-out fits."""
    return float(np.mean([log_likelihood(X[n:n + 1], f)[0] for n, f in enumerate(fits)]))


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
    return bool(np.all(np.linalg.eigvalsh(P) > PD_MIN_EIG))


def apply_zeros(P, entries):
    """Precision ``P (D, D)`` with the symmetric ``entries`` [(i, j), ...] set to zero; if that loses
    positive definiteness, those entries are shrunk towards zero only as far as it stays positive
    definite (bisection on a common factor; the original matrix is positive definite)."""
    if not entries:
        return P
    mask = np.zeros(P.shape, dtype=bool)
    for i, j in entries:
        mask[i, j] = mask[j, i] = True
    scaled = lambda s: np.where(mask, s * P, P)
    if is_positive_definite(scaled(0.0)):
        return scaled(0.0)
    lo, hi = 0.0, 1.0               # scaled(hi) is PD, scaled(lo) is not
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if is_positive_definite(scaled(mid)) else (mid, hi)
    return scaled(hi)


def sparsified(mix: Mixture, entries) -> Mixture:
    """The mixture with :func:`apply_zeros` applied to every component's precision."""
    return Mixture(mix.weights, mix.means, np.array([apply_zeros(P, entries) for P in mix.precisions]))


def greedy_zero_pattern(X, fits: list, candidates) -> tuple:
    """Greedy forward search over precision ``candidates`` [(i, j), ...] to zero: add, one at a time, the
    entry whose zeroing gives the best leave-one-out score of ``fits`` (the held-out fits of ``X``), as
    long as the score does not drop.  Returns ``(chosen entries, score without zeros, final score)``.
    The dissertation searches all patterns; a greedy search is the cheaper choice of §4.1.1's note."""
    base = current = loo_score(X, fits)
    chosen, left = [], list(candidates)
    while left:
        trial = [(loo_score(X, [sparsified(f, chosen + [e]) for f in fits]), e) for e in left]
        score, e = max(trial, key=lambda t: t[0])
        if score < current:
            break
        current = score
        chosen.append(e)
        left.remove(e)
    return chosen, base, current
