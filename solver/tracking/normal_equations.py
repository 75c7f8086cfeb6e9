"""Normal equations of point rows on a :class:`.blend_body.BlendBody`, assembled from lever arms without
forming the Jacobian (depth-camera tracking dissertation, Eq. 5.6 and 6.10): point rows
``J_m = [I, -[a_m0]x, ..., -[a_m,B-1]x]`` in the world-axes increments reduce to one ``(3B x 3B)`` Gram
matrix of the lever arms.  :meth:`System.linear` hands the sums out in the body's parameters
(``omega_b = A_b delta_b``, :meth:`.blend_body.BlendBody.axes`) as a :class:`.terms.Linear`, so they add
to the priors' and go to the solver like any other term's.

Energy convention of :class:`.terms.Linear`: ``1/2 sum w |r|^2`` for ``H = sum w J^T J``.
"""
from __future__ import annotations

import numpy as np

from .terms import Linear


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (broadcasting), without ``np.cross``'s axis handling."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) cross-product matrices ``[v]x``."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


class System:
    """Sums of weighted squared rows on one pose of a blend body (``posed``), in world-axes increments
    (``H`` (P, P), ``g`` (P,), ``sum_sq`` = sum w r^2) until :meth:`linear` turns them into the body's
    parameters."""

    def __init__(self, body, posed):
        self.body, self.posed = body, posed
        self.B, self.H, self.g, self.sum_sq = body.num_bones, np.zeros((body.size, body.size)), np.zeros(body.size), 0.0

    def add_points(self, a: np.ndarray, r: np.ndarray, w: np.ndarray) -> None:
        """Point rows: lever arms ``a`` (m, 3, B), residuals ``r`` (m, 3) = model - target, weights (m,).
        The sums over points are matrix products (one Gram matrix, six matrix-vector products)."""
        m, B = len(a), self.B
        if m == 0:
            return
        A = a.transpose(0, 2, 1).reshape(m, 3 * B)
        G = ((A * w[:, None]).T @ A).reshape(B, 3, B, 3)
        trace = np.einsum("jtkt->jk", G)
        blocks = trace[:, :, None, None] * np.eye(3) - G.transpose(0, 2, 3, 1)   # [j, k, r, s]
        H = self.H
        H[3:, 3:] += blocks.transpose(0, 2, 1, 3).reshape(3 * B, 3 * B)
        H[:3, :3] += w.sum() * np.eye(3)
        side = -skew(np.tensordot(w, a, axes=(0, 0)).T)                          # (B, 3, 3)
        H[:3, 3:] += side.transpose(1, 0, 2).reshape(3, 3 * B)
        H[3:, :3] += side.transpose(1, 0, 2).reshape(3, 3 * B).T
        wr = r * w[:, None]
        self.g[:3] += wr.sum(axis=0)
        a0, a1, a2 = a[:, 0].T, a[:, 1].T, a[:, 2].T                             # (B, m) each
        g = np.stack((a1 @ wr[:, 2] - a2 @ wr[:, 1], a2 @ wr[:, 0] - a0 @ wr[:, 2],
                      a0 @ wr[:, 1] - a1 @ wr[:, 0]), axis=1)                    # sum_m a_mj x (w r)_m
        self.g[3:] += g.reshape(-1)
        self.sum_sq += float((w * (r * r).sum(axis=1)).sum())

    def add_projected(self, a: np.ndarray, h: np.ndarray, e: np.ndarray, w: np.ndarray) -> None:
        """Scalar rows ``h_m . (point_m motion) = -e_m``: lever arms ``a`` (m, 3, B), directions ``h``
        (m, 3), residuals ``e`` (m,), weights (m,) (point-to-plane, edge and floor rows)."""
        if len(a) == 0:
            return
        rows = np.concatenate([h, cross(a.transpose(0, 2, 1), h[:, None, :]).reshape(len(a), -1)], axis=1)
        self.H += (rows * w[:, None]).T @ rows
        self.g += rows.T @ (w * e)
        self.sum_sq += float((w * e * e).sum())

    def linear(self) -> Linear:
        """The sums in the body's parameters: ``H_p = T^T H T``, ``g_p = T^T g`` with ``T`` the block
        diagonal of the identity (root translation) and the bones' axes."""
        B = self.B
        T = np.zeros((B + 1, 3, 3))
        T[0] = np.eye(3)
        T[1:] = self.body.axes(self.posed)
        n = 3 * (B + 1)
        left = np.swapaxes(T, 1, 2) @ self.H.reshape(B + 1, 3, n)                     # T_i^T H_ik
        Hp = (left.reshape(n, B + 1, 1, 3) @ T[None]).reshape(n, n)                    # ... T_k
        gp = (np.swapaxes(T, 1, 2) @ self.g.reshape(B + 1, 3, 1)).ravel()
        return Linear(Hp, gp, 0.5 * self.sum_sq)
