"""Dual quaternions for rigid motions and dual-quaternion linear blending (DLB, Kavan et al. 2008).

A dual quaternion is a float64 array ``(..., 8)``: ``[:4]`` the real part q0 (a unit quaternion
(w, x, y, z), the rotation) and ``[4:]`` the dual part qe.  The rigid motion x -> R x + t is
``q0 = quat(R)``, ``qe = ½ (0, t) · q0``.  A rotation by q about a centre c (x -> R (x - c) + c) has
``qe = ½ ((0, c)·q - q·(0, c)) = (0, c × u)`` for q = (w, u).

Points are mapped with the normalising formula of the model-adaptive mocap dissertation (§1.4), which is
rigid even when the blended dual quaternion is not exactly unit (⟨q0, qe⟩ ≠ 0):
``x' = x + 2 a × (a × x + a_w x) + 2 (a_w d − d_w a + a × d)`` with (a_w, a) = q0/|q0|, (d_w, d) = qe/|q0|.
"""
import numpy as np

from .rotations import quat_canonical, quat_mul, quat_to_matrix, matrix_to_quat

IDENTITY = np.array([1.0, 0, 0, 0, 0, 0, 0, 0])


def dq_rotation_about(q, centre):
    """Dual quaternions ``(..., 8)`` of "rotate by unit quaternion q ``(..., 4)`` about ``centre``
    ``(..., 3)``" (broadcasting), i.e. x -> R(q) (x - c) + c."""
    q = np.asarray(q, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    lead = np.broadcast_shapes(q.shape[:-1], c.shape[:-1])
    q = np.broadcast_to(q, lead + (4,))
    c = np.broadcast_to(c, lead + (3,))
    dual = np.concatenate([np.zeros(q.shape[:-1] + (1,)), np.cross(c, q[..., 1:])], axis=-1)
    return np.concatenate([q, dual], axis=-1)


def dq_from_rigid(R, t):
    """Dual quaternions ``(..., 8)`` of the rigid maps x -> R x + t, R ``(..., 3, 3)``, t ``(..., 3)``."""
    q0 = matrix_to_quat(R)
    t = np.asarray(t, dtype=np.float64)
    tq = np.concatenate([np.zeros(t.shape[:-1] + (1,)), t], axis=-1)
    q0, tq = np.broadcast_arrays(q0, tq)
    return np.concatenate([q0, 0.5 * quat_mul(tq, q0)], axis=-1)


def dq_to_rigid(dq):
    """Rotation ``(..., 3, 3)`` and translation ``(..., 3)`` of (possibly non-normalised) dual
    quaternions ``(..., 8)``, using the normalising formula of the module docstring."""
    dq = np.asarray(dq, dtype=np.float64)
    n = np.linalg.norm(dq[..., :4], axis=-1, keepdims=True)
    a = dq[..., :4] / n
    d = dq[..., 4:] / n
    aw, av, dw, dv = a[..., :1], a[..., 1:], d[..., :1], d[..., 1:]
    t = 2.0 * (aw * dv - dw * av + np.cross(av, dv))
    return quat_to_matrix(a), t


def dq_apply(dq, points):
    """Apply dual quaternions ``(..., 8)`` to points ``(..., 3)`` (broadcasting); the dual
    quaternions are normalised by |q0| (module docstring)."""
    dq = np.asarray(dq, dtype=np.float64)
    x = np.asarray(points, dtype=np.float64)
    n = np.linalg.norm(dq[..., :4], axis=-1, keepdims=True)
    a = dq[..., :4] / n
    d = dq[..., 4:] / n
    aw, av, dw, dv = a[..., :1], a[..., 1:], d[..., :1], d[..., 1:]
    rot = x + 2.0 * np.cross(av, np.cross(av, x) + aw * x)
    return rot + 2.0 * (aw * dv - dw * av + np.cross(av, dv))


def align_hemisphere(dq, pivot):
    """Flip dual quaternions ``(..., K, 8)`` whose real part has a negative dot product with the
    pivot quaternion ``(..., 4)`` (q̂ and −q̂ are the same motion; blending needs one hemisphere)."""
    dq = np.asarray(dq, dtype=np.float64)
    dots = np.einsum("...ki,...i->...k", dq[..., :4], np.asarray(pivot, dtype=np.float64))
    return np.where(dots[..., None] < 0, -dq, dq)


def _align_running(w, dq):
    """The sequential hemisphere rule of :func:`dlb` ("running"): weights (..., K), dq (..., K, 8)."""
    out = dq.copy()
    total = np.zeros(dq.shape[:-2] + (4,))
    total[..., 0] = 1.0 - w.sum(axis=-1)
    for k in range(dq.shape[-2]):
        flip = (np.einsum("...i,...i->...", out[..., k, :4], total) < 0) & (w[..., k] > 0)
        out[..., k, :] = np.where(flip[..., None], -out[..., k, :], out[..., k, :])
        total += w[..., k, None] * out[..., k, :4]
    return out


def dlb(weights, dq, pivot="identity"):
    """Dual-quaternion linear blend with a neutral (identity) remainder.

    weights ``(..., K)`` each in [0, 1] with sum <= 1; dq ``(..., K, 8)``.  The remainder
    ``1 − Σ w`` goes to the identity.  Inputs are first aligned to a hemisphere:
    ``"identity"`` (the neutral transform's), ``"max"`` (the input with the largest weight's) or
    ``"running"`` (Blender's Preserve Volume rule, used by the hybrid skin: the neutral first, then the
    inputs in order, each flipped when its real part points away from the weighted sum so far).  Every
    choice makes the result invariant to negating any input.  Returns the blended, *un-normalised* dual quaternions ``(..., 8)``; apply them
    with :func:`dq_apply` (which normalises)."""
    w = np.asarray(weights, dtype=np.float64)
    dq = np.asarray(dq, dtype=np.float64)
    if pivot == "running":
        dq = _align_running(w, dq)
        return np.einsum("...k,...ki->...i", w, dq) + (1.0 - w.sum(axis=-1))[..., None] * IDENTITY
    if pivot == "identity":
        piv = np.broadcast_to(IDENTITY[:4], dq.shape[:-2] + (4,))
    elif pivot == "max":
        k = np.argmax(w, axis=-1)
        piv = np.take_along_axis(dq[..., :4], k[..., None, None], axis=-2)[..., 0, :]
        piv = quat_canonical(piv)          # so the neutral identity is in the pivot's hemisphere
    else:
        raise ValueError(f"dlb: unknown pivot {pivot!r}")
    dq = align_hemisphere(dq, piv)
    blended = np.einsum("...k,...ki->...i", w, dq)
    return blended + (1.0 - w.sum(axis=-1))[..., None] * IDENTITY
