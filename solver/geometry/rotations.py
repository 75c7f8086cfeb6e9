"""Rotations: quaternions, rotation matrices and rotation vectors, vectorised over leading dimensions.

Conventions:
* quaternions are float64 arrays ``(..., 4)`` ordered (w, x, y, z), Hamilton product;
* rotation matrices are ``(..., 3, 3)`` acting on column vectors (``R @ v``);
* rotation vectors are ``(..., 3)`` with angle = norm in radians (full-angle convention, NOT the
  half-angle convention of the thesis' Eq. 3.22);
* the twist axis of a bone is its local +Y axis.
"""
import numpy as np

_EPS_TWIST = 1e-12


def _as_quat(q):
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion array must end in 4 components, got shape {q.shape}")
    return q


def quat_mul(a, b):
    """Hamilton product ``a·b`` of quaternions ``(..., 4)`` (broadcasting)."""
    a, b = _as_quat(a), _as_quat(b)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_conj(q):
    """Conjugate (w, -x, -y, -z); the inverse of a unit quaternion."""
    q = _as_quat(q)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q):
    """``q / |q|`` over the last axis (zero quaternions become the identity)."""
    q = _as_quat(q)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    zero = n == 0
    out = q / np.where(zero, 1.0, n)
    return np.where(zero, np.array([1.0, 0.0, 0.0, 0.0]), out)


def quat_canonical(q):
    """The same rotation with w >= 0 (q and -q are the same rotation)."""
    q = _as_quat(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_sign_continuous(q):
    """Quaternions ``(N, ..., 4)`` flipped so each has a non-negative dot product with the one before it
    along axis 0 (frames), so keys interpolated between them take the short way."""
    q = np.array(_as_quat(q), dtype=np.float64)
    for n in range(1, len(q)):
        flip = np.einsum("...i,...i->...", q[n], q[n - 1]) < 0
        q[n][flip] *= -1
    return q


def quat_to_matrix(q):
    """Rotation matrices ``(..., 3, 3)`` of quaternions ``(..., 4)`` (normalised first)."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    rows = [
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ]
    return np.stack(rows, axis=-1).reshape(w.shape + (3, 3))


def matrix_to_quat(R):
    """Unit quaternions (w >= 0) of rotation matrices ``(..., 3, 3)`` (Shepperd's method: the
    largest of 4w², 4x², 4y², 4z² is used as pivot, so the result is accurate for every angle)."""
    R = np.asarray(R, dtype=np.float64)
    m = R.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    diag = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=-1)
    k = np.argmax(diag, axis=-1)
    d21, d02, d10 = m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]
    s01, s02, s12 = m[:, 0, 1] + m[:, 1, 0], m[:, 0, 2] + m[:, 2, 0], m[:, 1, 2] + m[:, 2, 1]
    cand = np.stack([
        np.stack([1 + tr, d21, d02, d10], -1),
        np.stack([d21, 1 + 2 * m[:, 0, 0] - tr, s01, s02], -1),
        np.stack([d02, s01, 1 + 2 * m[:, 1, 1] - tr, s12], -1),
        np.stack([d10, s02, s12, 1 + 2 * m[:, 2, 2] - tr], -1),
    ], axis=1)
    q = cand[np.arange(len(k)), k]
    q = quat_canonical(quat_normalize(q))
    return q.reshape(R.shape[:-2] + (4,))


def rotvec_to_quat(r):
    """Exponential map: rotation vectors ``(..., 3)`` (angle = norm) to unit quaternions ``(..., 4)``.
    Stable at 0 (uses sinc) and for any angle."""
    r = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(r, axis=-1, keepdims=True)
    half_sinc = 0.5 * np.sinc(theta / (2 * np.pi))      # sin(theta/2)/theta, exact 0.5 at 0
    return np.concatenate([np.cos(0.5 * theta), half_sinc * r], axis=-1)


def quat_to_rotvec(q):
    """Logarithm: unit quaternions ``(..., 4)`` to rotation vectors ``(..., 3)`` with angle in
    [0, pi] (q is normalised and flipped to w >= 0 first).  Stable near 0 and near pi."""
    q = quat_canonical(quat_normalize(q))
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    small = s < 1e-300
    factor = np.where(small, 2.0 / np.maximum(q[..., :1], 1e-300), angle / np.where(small, 1.0, s))
    return factor * v


def rotvec_to_matrix(r):
    """Rotation matrices ``(..., 3, 3)`` of rotation vectors ``(..., 3)`` (angle = norm)."""
    return quat_to_matrix(rotvec_to_quat(r))


def rotation_between(a, b):
    """``(..., 3, 3)`` smallest rotations taking unit vectors ``a (..., 3)`` onto unit vectors ``b (..., 3)``
    (broadcasting), about their common perpendicular: ``I + K + K² / (1 + a·b)`` with ``K = [a × b]×``; a
    half turn about an axis normal to ``a`` where they are opposite."""
    a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
    v, c = np.cross(a, b), np.einsum("...i,...i->...", a, b)
    K = np.zeros(v.shape + (3,))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K -= np.swapaxes(K, -1, -2)
    opposite = c < -1.0 + 1e-9
    out = np.eye(3) + K + (K @ K) / np.where(opposite, 1.0, 1.0 + c)[..., None, None]
    if opposite.any():
        ao = a[opposite]
        w = np.cross(ao, np.eye(3)[np.argmin(np.abs(ao), axis=-1)])
        w /= np.linalg.norm(w, axis=-1, keepdims=True)
        out[opposite] = 2.0 * w[:, :, None] * w[:, None, :] - np.eye(3)
    return out


def quat_apply(q, v):
    """Rotate vectors ``(..., 3)`` by unit quaternions ``(..., 4)`` (broadcasting): q v q*."""
    q = _as_quat(q)
    v = np.asarray(v, dtype=np.float64)
    w = q[..., :1]
    u = q[..., 1:]
    uv = np.cross(u, v)
    return v + 2.0 * (w * uv + np.cross(u, uv))


def swing_twist_y(q):
    """Split unit quaternions ``(..., 4)`` into ``(q_swing, q_twist)`` with ``q = q_swing · q_twist``.

    The twist is the rotation about the local Y axis: after flipping q to w >= 0,
    ``q_twist = (w, 0, y, 0) / sqrt(w² + y²)`` (identity when w² + y² ≈ 0, a swing of 180°), so the
    twist angle lies in (-pi, pi] and ``q_twist`` has w >= 0.  ``q_swing = q · q_twist*`` has a zero
    Y component: it is the shortest-arc rotation taking Y to the posed Y axis."""
    q = quat_canonical(quat_normalize(q))
    w, y = q[..., 0], q[..., 2]
    n2 = w * w + y * y
    ok = n2 > _EPS_TWIST
    n = np.sqrt(np.where(ok, n2, 1.0))
    twist = np.zeros_like(q)
    twist[..., 0] = np.where(ok, w / n, 1.0)
    twist[..., 2] = np.where(ok, y / n, 0.0)
    swing = quat_mul(q, quat_conj(twist))
    return swing, twist
