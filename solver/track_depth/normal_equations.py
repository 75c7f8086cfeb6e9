"""Normal equations of the linearised pose update (depth-camera tracking dissertation, Eq. 5.6 and 6.10),
assembled without forming the Jacobian: point rows ``J_m = [I, -[a_m0]x, ..., -[a_m,B-1]x]``
(:meth:`.body.TrackingBody.lever_arms`) reduce to one ``(3B x 3B)`` Gram matrix of the lever arms.

Parameter vector (3 + 3B): root translation, then one world-axes rotation vector per joint.
"""
from __future__ import annotations

import numpy as np


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
    """``H`` (P, P) and ``g`` (P,) of ``E = sum of weighted squared residual rows``; ``solve`` returns the
    step minimising the quadratic model plus ``damping |step|^2`` (the dissertation's lambda_r term)."""

    def __init__(self, num_bones: int):
        P = 3 + 3 * num_bones
        self.B, self.H, self.g, self.energy = num_bones, np.zeros((P, P)), np.zeros(P), 0.0

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
        self.energy += float((w * (r * r).sum(axis=1)).sum())

    def add_projected(self, a: np.ndarray, h: np.ndarray, e: np.ndarray, w: np.ndarray) -> None:
        """Scalar rows ``h_m . (point_m motion) = -e_m``: lever arms ``a`` (m, 3, B), directions ``h``
        (m, 3), residuals ``e`` (m,), weights (m,) (the edge rows of Eq. 5.4)."""
        if len(a) == 0:
            return
        rows = np.concatenate([h, cross(a.transpose(0, 2, 1), h[:, None, :]).reshape(len(a), -1)], axis=1)
        self.add_rows(rows, e, w)

    def add_rows(self, rows: np.ndarray, e: np.ndarray, w: np.ndarray) -> None:
        """Dense rows (m, P) with residuals (m,) and weights (m,)."""
        self.H += (rows * w[:, None]).T @ rows
        self.g += rows.T @ (w * e)
        self.energy += float((w * e * e).sum())

    def add_blocks(self, cols: np.ndarray, D: np.ndarray, e: np.ndarray, w: np.ndarray) -> None:
        """Rows that each touch one joint's three parameters: ``cols`` (k, 3) the joints' parameter ids,
        ``D`` (k, 3, 3) three rows per joint on them, residuals ``e`` (k, 3), weights ``w`` (k, 3); the
        same as :meth:`add_rows` on the dense rows, summed block by block."""
        wD = D * w[:, :, None]
        self.H[cols[:, :, None], cols[:, None, :]] += np.swapaxes(D, 1, 2) @ wD
        self.g[cols] += np.einsum("kri,kr->ki", wD, e)
        self.energy += float((w * e * e).sum())

    def add_diagonal(self, index, weight: float, target=None) -> None:
        """``weight |x[index] - target|^2`` rows on single parameters (target 0 by default)."""
        idx = np.asarray(index)
        self.H[idx, idx] += weight
        if target is not None:
            self.g[idx] -= weight * np.asarray(target)

    def solve(self, damping: float) -> np.ndarray:
        H = self.H + damping * np.eye(len(self.g))
        try:
            return -np.linalg.solve(H, self.g)
        except np.linalg.LinAlgError:
            return -np.linalg.lstsq(H, self.g, rcond=None)[0]
