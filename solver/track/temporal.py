"""The temporal prior of tracking: second differences of the joints' rotations over consecutive frames.

Model-adaptive mocap dissertation §4.1.3, Eq. 4.9-4.10:

    Q^temp = 1/(N−2) Σ_{n=1}^{N−2} Q_n^temp,   Q_n^temp = (1/J) Σ_j ‖r_j^n − ½ (r_j^{n−1} + r_j^{n+1})‖²

(frames 0..N−1), an acceleration penalty on the bone-local exp-map vectors ``r = log(q)`` (angle = norm,
radians) of the pose quaternions, as :mod:`solver.tracking.pose_prior` uses them.  The joints are bones 1..B−1
(J = B − 1): like the equation, the root's rotation and translation and the uniform scale are not part of
it.  Normalised by the frame count and J as the equation is (§4.1.5's text says J×3; the equation
divides by J).  Equal frame intervals are assumed.  Fewer than 3 frames: no term (0).

For Levenberg–Marquardt the residuals are ``e = sqrt(1/((N−2) J)) (r_n − ½ r_{n−1} − ½ r_{n+1})`` so that
``Q^temp = Σ e²``; their Jacobian with respect to the pose increments of
:func:`solver.rig.jacobians.pose_layout` (``q_b ← q_b exp(δ_b)`` per frame) chains through
``d r / d δ`` (:func:`solver.tracking.pose_prior.rotvec_increment_jacobian`, finite at every angle).  A rotation whose
angle crosses π between frames makes r jump (the log is taken with angles in [0, π]): joints never get
there.  :func:`temporal_weight` is the weight heuristic of Eq. 4.16.
"""
import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import quat_to_rotvec
from ..tracking.pose_prior import rotvec_increment_jacobian

MIN_TEMP = (np.pi / 180.0 * 0.1) ** 2   # floor of Q^temp in temporal_weight (rad²): 0.1° of acceleration
MIN_MOTION = (np.pi / 180.0) ** 2       # floor of the joints' mean squared motion in motion_weight: 1°/frame


def _rotations(rotations) -> np.ndarray:
    q = np.asarray(rotations, dtype=np.float64)
    if q.ndim != 3 or q.shape[2] != 4 or q.shape[1] < 1:
        raise ArticulaInputError(f"temporal prior: rotations of shape {q.shape}, expected (N, B, 4)")
    if not np.isfinite(q).all():
        raise ArticulaInputError("temporal prior: non-finite rotations")
    return q


def _scale(N, J) -> float:
    return 1.0 / np.sqrt((N - 2) * J) if N >= 3 and J else 0.0


def residuals(rotations) -> np.ndarray:
    """``(max(N−2, 0), J, 3)`` residuals e (module docstring) of the pose quaternions ``(N, B, 4)``;
    ``Q^temp = Σ e²``."""
    q = _rotations(rotations)
    N, J = len(q), q.shape[1] - 1
    if N < 3:
        return np.zeros((0, J, 3))
    r = quat_to_rotvec(q[:, 1:])
    return _scale(N, J) * (r[1:-1] - 0.5 * (r[:-2] + r[2:]))


def value(rotations) -> float:
    """Q^temp (rad², Eq. 4.9-4.10) of the pose quaternions ``(N, B, 4)``; 0 for fewer than 3 frames."""
    e = residuals(rotations)
    return float(np.einsum("nji,nji->", e, e))


def frame_values(rotations) -> np.ndarray:
    """``(N,)`` Q_n^temp of every frame (rad², Eq. 4.10; 0 at the first and last frame, where it is not
    defined), e.g. to find frames that jerk."""
    q = _rotations(rotations)
    out = np.zeros(len(q))
    if len(q) >= 3 and q.shape[1] > 1:
        e = residuals(q) / _scale(len(q), q.shape[1] - 1)
        out[1:-1] = np.einsum("nji,nji->n", e, e) / (q.shape[1] - 1)
    return out


def jacobian(rotations) -> np.ndarray:
    """``(N−2, J, 3, N, 4 + 3B)`` derivative of the residuals with respect to every frame's pose
    increments (columns of :func:`solver.rig.jacobians.pose_layout`; translation, scale and root columns
    are zero).  Row (n, j) (the residual centred on frame n+1) holds ``s Jr(r_j^m)`` in frame m = n+1's
    columns of bone j+1 and ``−s/2 Jr(r_j^m)`` in those of m = n and n+2, with ``Jr = d r / d δ`` and s the
    residual scale."""
    q = _rotations(rotations)
    N, B = q.shape[:2]
    J = B - 1
    out = np.zeros((max(N - 2, 0), J, 3, N, 4 + 3 * B))
    if N < 3 or not J:
        return out
    Jr = _scale(N, J) * rotvec_increment_jacobian(quat_to_rotvec(q[:, 1:]))       # (N, J, 3, 3)
    n = np.arange(N - 2)
    for offset, factor in ((0, -0.5), (1, 1.0), (2, -0.5)):
        for b in range(1, B):
            out[n, b - 1, :, n + offset, 4 + 3 * b:7 + 3 * b] = factor * Jr[n + offset, b - 1]
    return out


def temporal_weight(q_data, rotations, min_temp: float = MIN_TEMP) -> float:
    """The weight heuristic of Eq. 4.16, ``w_temp ≈ Q^data / Q^temp``, both at rough poses (e.g. the
    per-frame fits of pass 1): ``q_data`` Q^data (m; a scalar or per-frame values, averaged), Q^temp of
    ``rotations (N, B, 4)`` (N >= 3) floored at ``min_temp`` (rad²) so that smooth or constant poses give a
    finite weight.  Returns a finite positive weight (m / rad²)."""
    q_data = np.asarray(q_data, dtype=np.float64)
    if q_data.size == 0 or not np.isfinite(q_data).all() or (q_data <= 0).any():
        raise ArticulaInputError("temporal weight: Q^data must be finite and positive")
    if not (np.isfinite(min_temp) and min_temp > 0):
        raise ArticulaInputError(f"temporal weight: min_temp must be finite and positive, got {min_temp}")
    q = _rotations(rotations)
    if len(q) < 3:
        raise ArticulaInputError(f"temporal weight: needs at least 3 frames, got {len(q)}")
    return float(q_data.mean() / max(value(q), min_temp))


class MotionPrior:
    """The temporal prior of one frame whose predecessors are fixed (pass 1 of tracking): the second
    difference of Eq. 4.10 taken one-sided, ``Q = (w / J) Σ_j ‖r_j − r̂_j‖²`` with the prediction
    ``r̂ = 2 r^{n−1} − r^{n−2}`` (constant angular velocity; ``r^{n−1}`` alone when only one frame is
    known), joints 1..B−1 as in Eq. 4.10.  ``previous (k, B, 4)``: the last k (1 or 2) poses' rotations,
    oldest first; ``weight`` (m / rad², the unit of w_temp)."""

    def __init__(self, previous, weight: float):
        q = _rotations(previous)
        r = quat_to_rotvec(q[-2:, 1:])
        self.target = 2.0 * r[-1] - r[0] if len(r) == 2 else r[-1]              # (J, 3)
        self.weight = float(weight)
        self.J = q.shape[1] - 1

    def _residuals(self, rotations):
        r = quat_to_rotvec(np.asarray(rotations, dtype=np.float64)[1:])
        return np.sqrt(self.weight / max(self.J, 1)) * (r - self.target), r

    def value(self, rotations) -> float:
        """Q of one frame's rotations ``(B, 4)``."""
        e = self._residuals(rotations)[0]
        return float(np.einsum("ji,ji->", e, e))

    def system(self, rotations, size):
        """Normal equations ``(H (size, size), g (size,), Q)`` in the pose-layout columns (bone b at
        ``4 + 3b``), ``d r / d δ`` from :func:`solver.tracking.pose_prior.rotvec_increment_jacobian`."""
        e, r = self._residuals(rotations)
        Jr = np.sqrt(self.weight / max(self.J, 1)) * rotvec_increment_jacobian(r)          # (J, 3, 3)
        H, g = np.zeros((size, size)), np.zeros(size)
        for j in range(self.J):
            s = slice(4 + 3 * (j + 1), 7 + 3 * (j + 1))
            H[s, s] = Jr[j].T @ Jr[j]
            g[s] = Jr[j].T @ e[j]
        return H, g, float(np.einsum("ji,ji->", e, e))


def motion_weight(share: float, q_data: float, previous, min_motion: float = MIN_MOTION) -> float:
    """Weight of :class:`MotionPrior` after Eq. 4.16's heuristic: the prior, at the joints' latest motion,
    costs ``share`` of the data term: ``w = share Q^data / max(m, min_motion)`` with ``m`` the mean over
    joints of ``‖r^{n−1} − r^{n−2}‖²`` (rad²) of ``previous (2, B, 4)`` and ``q_data`` the last frame's
    Q^data (m).  Fast motion or clean data -> a weak pull; slow motion or noisy data -> a strong one."""
    q = _rotations(previous)
    if len(q) != 2:
        raise ArticulaInputError(f"motion weight: expected the rotations of 2 frames, got {len(q)}")
    if not (np.isfinite(q_data) and q_data > 0 and np.isfinite(share) and share >= 0):
        raise ArticulaInputError("motion weight: Q^data must be finite and positive, share finite and >= 0")
    r = quat_to_rotvec(q[:, 1:])
    m = float(np.mean(np.sum((r[1] - r[0]) ** 2, axis=-1))) if q.shape[1] > 1 else 0.0
    return float(share * q_data / max(m, min_motion))
