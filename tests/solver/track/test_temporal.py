"""Temporal prior of tracking (solver.track.temporal, Eq. 4.9-4.10): zero for constant angular velocity,
the closed form for one jittered frame, the root left out, the Jacobian against central differences and
the weight heuristic of Eq. 4.16 (T13, T22)."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.jacobians import apply_pose_increment
from articula.solver.rig.model import Poses
from articula.solver.track import temporal

B, N = 6, 7


def _linear(rng, n=N, b=B):
    """Quaternions of rotation vectors r(t) = r0 + t v (constant angular velocity about a fixed axis is a
    special case; here every component moves linearly), angles within 2.4 rad."""
    r0 = rng.uniform(-0.6, 0.6, (b, 3))
    v = rng.uniform(-0.12, 0.12, (b, 3))
    r = r0 + np.arange(n)[:, None, None] * v
    return rotvec_to_quat(r), r


def test_constant_velocity_gives_zero_and_jitter_the_closed_form():
    """T13: Q^temp = 0 (to rounding) for r linear in t; a jitter d on joint j of one interior frame k gives
    residuals d, −d/2, −d/2 at frames k, k±1, so Q^temp = 1.5 |d|² / ((N−2) J)."""
    rng = np.random.default_rng(0)
    q, r = _linear(rng)
    assert temporal.value(q) < 1e-28 and np.abs(temporal.frame_values(q)).max() < 1e-28
    d = np.array([0.02, -0.01, 0.03])
    r[3, 2] += d
    jittered = rotvec_to_quat(r)
    assert temporal.value(jittered) == pytest.approx(1.5 * d @ d / ((N - 2) * (B - 1)), rel=1e-9)
    fv = temporal.frame_values(jittered)
    assert fv[0] == fv[-1] == 0 and fv[3] == pytest.approx(d @ d / (B - 1), rel=1e-9)
    assert fv[2] == pytest.approx(0.25 * d @ d / (B - 1), rel=1e-9) and abs(fv[1]) < 1e-28


def test_root_rotation_and_fewer_than_three_frames_take_no_part():
    """The equation has the joints only: a jerking root rotation changes nothing; N < 3: no term."""
    rng = np.random.default_rng(1)
    q, _ = _linear(rng)
    jerk = q.copy()
    jerk[:, 0] = rotvec_to_quat(rng.normal(size=(N, 3)))
    assert temporal.value(jerk) == temporal.value(q)
    assert temporal.value(q[:2]) == 0.0 and temporal.residuals(q[:2]).shape == (0, B - 1, 3)
    assert temporal.jacobian(q[:2]).shape == (0, B - 1, 3, 2, 4 + 3 * B)


def test_jacobian_matches_central_differences():
    """Residuals of poses moved by pose increments δ (q ← q exp(δ), every frame and bone, translation and
    scale too) by central differences, against the analytic Jacobian; one joint near 2.9 rad."""
    rng = np.random.default_rng(2)
    r = rng.uniform(-1.0, 1.0, (N, B, 3))
    r[:, 3] = 2.9 * np.array([0.0, 0.6, 0.8]) + 0.05 * rng.normal(size=(N, 3))
    poses = Poses(rotvec_to_quat(r), rng.normal(size=(N, 3)), np.ones(N))
    P = 4 + 3 * B
    Ja = temporal.jacobian(poses.rotations).reshape(-1, N * P)
    h = 1e-6

    def res(delta):
        return temporal.residuals(apply_pose_increment(poses, delta.reshape(N, P)).rotations).ravel()
    Jfd = np.stack([(res(h * e) - res(-h * e)) / (2 * h) for e in np.eye(N * P)], axis=1)
    assert np.abs(Ja - Jfd).max() < 1e-7 * np.abs(Jfd).max()
    assert np.abs(Jfd).max() > 0.1
    cols = Ja.reshape(-1, N, P)
    assert (cols[:, :, :7] == 0).all()                         # translation, scale, root rotation


def test_temporal_weight_heuristic_is_finite_and_positive():
    """T22 (w_temp part): Q^data / Q^temp at rough poses; constant poses fall back on the floor; bad input
    is refused."""
    rng = np.random.default_rng(3)
    q, r = _linear(rng)
    r = r + rng.normal(scale=0.02, size=r.shape)
    rough = rotvec_to_quat(r)
    w = temporal.temporal_weight([0.004, 0.006], rough)
    assert np.isfinite(w) and w > 0 and w == pytest.approx(0.005 / temporal.value(rough))
    still = np.repeat(q[:1], 5, axis=0)
    assert temporal.temporal_weight(0.005, still) == pytest.approx(0.005 / temporal.MIN_TEMP)
    for args, msg in (((0.0, rough), "Q\\^data"), ((np.nan, rough), "Q\\^data"), ((0.005, rough[:2]), "3 frames"),
                      ((0.005, rough[..., :3]), "shape")):
        with pytest.raises(ArticulaInputError, match=msg):
            temporal.temporal_weight(*args)


def test_residuals_are_the_bone_local_log_of_the_quaternions():
    """e = s (r_n − (r_{n−1} + r_{n+1}) / 2) with r the log of the (possibly sign-flipped) quaternions."""
    rng = np.random.default_rng(4)
    q, _ = _linear(rng)
    q[2] *= -1.0                                                 # the same rotations
    r = quat_to_rotvec(q[:, 1:])
    want = (r[1:-1] - 0.5 * (r[:-2] + r[2:])) / np.sqrt((N - 2) * (B - 1))
    assert np.allclose(temporal.residuals(q), want, atol=1e-15)


def test_motion_prior_targets_the_previous_frame_or_the_constant_velocity_prediction():
    """Pass 1's one-frame term: zero at the previous pose (one frame known) and at 2 r^{n−1} − r^{n−2}
    (two known), the closed form (w / J)|d|² for a joint moved by d, the root left out."""
    rng = np.random.default_rng(4)
    q, r = _linear(rng, n=3)
    w = 0.3
    assert temporal.MotionPrior(q[1:2], w).value(q[1]) == 0.0
    assert temporal.MotionPrior(q[:2], w).value(q[2]) < 1e-28
    moved = r[1].copy()
    d = np.array([0.01, -0.02, 0.015])
    moved[2] += d
    moved[0] += 0.5                                                   # the root: no part
    assert temporal.MotionPrior(q[1:2], w).value(rotvec_to_quat(moved)) == pytest.approx(w * d @ d / (B - 1),
                                                                                         rel=1e-9)


def test_motion_prior_normal_equations_match_central_differences():
    """``system`` returns the Gauss-Newton H = JᵀJ and g = Jᵀe of Q in the pose-layout columns: g against
    central differences of Q / 2 under q ← q exp(δ), H against JᵀJ of the residuals' differences."""
    rng = np.random.default_rng(5)
    prev = rotvec_to_quat(rng.uniform(-1.0, 1.0, (2, B, 3)))
    cur = Poses(rotvec_to_quat(rng.uniform(-1.0, 1.0, (1, B, 3))), np.zeros((1, 3)), np.ones(1))
    prior = temporal.MotionPrior(prev, 0.7)
    P = 4 + 3 * B
    H, g, Q = prior.system(cur.rotations[0], P)
    assert Q == pytest.approx(prior.value(cur.rotations[0]), rel=1e-12)
    h = 1e-6
    J = np.zeros((3 * (B - 1), P))
    for k in range(P):
        d = np.zeros((1, P))
        d[0, k] = h
        up, down = apply_pose_increment(cur, d).rotations[0], apply_pose_increment(cur, -d).rotations[0]
        assert (prior.value(up) - prior.value(down)) / (4 * h) == pytest.approx(g[k], abs=1e-7)
        J[:, k] = (prior._residuals(up)[0] - prior._residuals(down)[0]).ravel() / (2 * h)
    assert np.allclose(H, J.T @ J, atol=1e-6)
    assert not H[:7].any() and not g[:7].any()                       # translation, scale and root: free


def test_motion_weight_follows_the_data_term_and_the_latest_motion():
    """w = share Q^data / mean_j |r^{n−1} − r^{n−2}|²: the closed form for a known motion, the 1°/frame
    floor for a still body, the root left out; bad inputs refused."""
    rng = np.random.default_rng(6)
    q, r = _linear(rng, n=2)
    m = np.mean(np.sum((r[1, 1:] - r[0, 1:]) ** 2, axis=-1))
    assert temporal.motion_weight(0.1, 0.004, q) == pytest.approx(0.1 * 0.004 / m, rel=1e-9)
    still = np.stack([q[0], q[0]])
    still[1, 0] = q[1, 0]                                              # only the root moved
    assert temporal.motion_weight(0.1, 0.004, still) == pytest.approx(0.1 * 0.004 / temporal.MIN_MOTION)
    assert temporal.motion_weight(0.0, 0.004, q) == 0.0
    for args in ((0.1, 0.0, q), (0.1, np.nan, q), (-1.0, 0.004, q), (0.1, 0.004, q[:1])):
        with pytest.raises(ArticulaInputError, match="motion weight"):
            temporal.motion_weight(*args)
