"""The robust data term of tracking: the Charbonnier norm and its IRLS weights.

Model-adaptive mocap dissertation §4.1.3, Eq. 4.4-4.6: ``Q_n^data = (1/C_n) sum_c |e_c|_*`` over the C_n
correspondences of frame n, with the Charbonnier norm ``|e|_* = sqrt(|e|^2 + eps^2)`` of the 3-D
residual's length (a smooth stand-in for L1), minimised by iteratively reweighted least squares:
each step minimises ``sum_c w_c |e_c|^2 / 2`` with ``w_c = 1 / |e_c|_*`` held fixed.

Units: metres.  The dissertation's "eps = 0.00001" was written for its metre-scale FAUST runs and
its millimetre-scale BUFF runs alike; Articula works in metres and uses ``eps = 1 mm``
(:data:`EPS_M`): below the noise of depth scans (several mm), so residuals of that size are still
weighted as in L1, while a pair that happens to match exactly gets a weight of at most 1/eps instead
of an unbounded one (with eps = 1e-5 m a single exact pair would outweigh a thousand 1 cm pairs).
:data:`FLOOR_M` clamps the weights for callers who choose a smaller eps.
"""
from __future__ import annotations

import numpy as np

EPS_M = 1e-3      # Charbonnier eps, metres
FLOOR_M = 1e-5    # weights never exceed 1 / FLOOR_M (1/m), whatever eps


def residual_lengths(residuals):
    """``(P,)`` lengths of ``(P, 3)`` residuals, or the input itself when it is already ``(P,)``."""
    e = np.asarray(residuals, dtype=np.float64)
    return np.linalg.norm(e, axis=1) if e.ndim == 2 else np.abs(e)


def charbonnier(residuals, eps=EPS_M):
    """``(P,)`` Charbonnier norms ``sqrt(|e|^2 + eps^2)`` (m) of residuals ``(P, 3)`` or lengths ``(P,)``."""
    r = residual_lengths(residuals)
    return np.sqrt(r * r + eps * eps)


def irls_weights(residuals, eps=EPS_M, floor=FLOOR_M):
    """``(P,)`` IRLS weights ``1 / sqrt(|e|^2 + eps^2)`` (1/m), clamped to at most ``1 / floor``."""
    return np.minimum(1.0 / np.maximum(charbonnier(residuals, eps), 1e-300), 1.0 / floor)


def data_energy(residuals, eps=EPS_M):
    """``Q_n^data = (1/C_n) sum |e|_*`` (m) of one frame's ``C_n`` residuals; 0.0 when there are none."""
    r = residual_lengths(residuals)
    return float(charbonnier(r, eps).mean()) if len(r) else 0.0
