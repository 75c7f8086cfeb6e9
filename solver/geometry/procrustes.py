"""Orthogonal Procrustes (Kabsch): the best rigid transform between corresponding point sets.

``fit_rigid(src, dst)`` returns ``R, t`` minimising ``Σ_i w_i ‖R src_i + t − dst_i‖²`` with ``det R = +1``
(a reflection is never returned).  Everything is vectorised over leading batch dimensions so all
parts × all scans are fitted in one call.  Units are those of the input (metres in Articula).
"""
import numpy as np


def fit_rigid(src, dst, weights=None):
    """Weighted rigid fit from ``src`` to ``dst``.

    src, dst: ``(..., P, 3)`` corresponding points (the batch dimensions broadcast);
    weights: optional ``(..., P)`` non-negative weights (default all 1; at least one positive).
    Returns ``R (..., 3, 3)`` proper rotations and ``t (..., 3)`` such that ``R @ src + t ≈ dst``.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if weights is None:
        weights = np.ones(np.broadcast_shapes(src.shape, dst.shape)[:-1])
    w = np.asarray(weights, dtype=np.float64)
    wsum = w.sum(axis=-1)[..., None]
    mu_s = (w[..., None] * src).sum(axis=-2) / wsum
    mu_d = (w[..., None] * dst).sum(axis=-2) / wsum
    cov = np.einsum("...p,...pi,...pj->...ij", w, dst - mu_d[..., None, :], src - mu_s[..., None, :])
    R = rotation_from_covariance(cov)
    t = mu_d - np.einsum("...ij,...j->...i", R, mu_s)
    return R, t


def rotation_from_covariance(cov):
    """The proper rotation maximising ``trace(Rᵀ cov)`` for ``cov (..., 3, 3)`` (SVD with the
    reflection fix: the smallest singular direction is flipped when ``det(U Vᵀ) < 0``)."""
    U, _, Vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    D = np.ones(U.shape[:-2] + (3,))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt


def fit_parts(rest, scans, labels, k):
    """Rigid transform of every part in every scan.

    rest: ``(V,3)`` rest vertices; scans: ``(M,V,3)``; labels: ``(V,)`` part index in ``[0,k)``.
    Returns ``R (M,k,3,3)``, ``t (M,k,3)`` with ``scans[m,v] ≈ R[m,labels[v]] rest[v] + t[m,labels[v]]``.
    Parts with no vertex get the identity.  Vectorised through per-part weighted moments.
    """
    rest = np.asarray(rest, dtype=np.float64)
    scans = np.asarray(scans, dtype=np.float64)
    onehot = np.zeros((rest.shape[0], k))
    onehot[np.arange(rest.shape[0]), labels] = 1.0
    return fit_rigid_soft(rest, scans, onehot)


def fit_rigid_soft(rest, scans, W):
    """Rigid transform per column of a vertex-weight matrix ``W (V,k)`` (e.g. one-hot labels) and per
    scan, computed from weighted first and second moments (no per-part copies of the points).
    Returns ``R (M,k,3,3)``, ``t (M,k,3)``; columns with zero total weight give the identity."""
    wsum = W.sum(axis=0)                                     # (k,)
    safe = np.where(wsum > 0, wsum, 1.0)
    mu_s = (W.T @ rest) / safe[:, None]                      # (k,3)
    mu_d = np.einsum("vk,mvi->mki", W, scans, optimize=True) / safe[None, :, None]
    # Σ_v w (d − μd)(s − μs)ᵀ = Σ_v w d sᵀ − wsum μd μsᵀ
    cross = np.einsum("vk,mvi,vj->mkij", W, scans, rest, optimize=True)
    cov = cross - wsum[None, :, None, None] * mu_d[..., :, None] * mu_s[None, :, None, :]
    R = rotation_from_covariance(cov)
    R = np.where((wsum > 0)[None, :, None, None], R, np.eye(3))
    t = mu_d - np.einsum("mkij,kj->mki", R, mu_s)
    return R, t
