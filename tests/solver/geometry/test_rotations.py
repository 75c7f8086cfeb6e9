"""Quaternions, rotation vectors and the swing/twist split (spec §8.1 S1, S4) against closed forms."""
import numpy as np
import pytest

from articula.solver.geometry import rotations as rot

RNG = np.random.default_rng(7)


def rodrigues(r):
    """Independent reference: R = I + sin θ K + (1 − cos θ) K² for one rotation vector."""
    th = np.linalg.norm(r)
    if th == 0:
        return np.eye(3)
    k = r / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def random_quats(n):
    return rot.quat_normalize(RNG.normal(size=(n, 4)))


def test_quat_mul_matches_matrix_product_and_conj_inverts():
    a, b = random_quats(50), random_quats(50)
    np.testing.assert_allclose(rot.quat_to_matrix(rot.quat_mul(a, b)),
                               rot.quat_to_matrix(a) @ rot.quat_to_matrix(b), atol=1e-14)
    ident = rot.quat_mul(a, rot.quat_conj(a))
    np.testing.assert_allclose(ident, np.tile([1.0, 0, 0, 0], (50, 1)), atol=1e-15)


def test_rotvec_to_matrix_matches_rodrigues_all_angles():
    r = RNG.normal(size=(40, 3))
    r *= (np.linspace(0, np.pi, 40) / np.linalg.norm(r, axis=1))[:, None]
    ref = np.array([rodrigues(x) for x in r])
    np.testing.assert_allclose(rot.rotvec_to_matrix(r), ref, atol=1e-14)


def test_exp_map_basics_S1():
    np.testing.assert_array_equal(rot.rotvec_to_quat(np.zeros(3)), [1, 0, 0, 0])
    r = RNG.normal(size=(100, 3)) * 2
    q = rot.rotvec_to_quat(r)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1, atol=1e-15)
    # full-angle convention: angle of the rotation = |r|  (cos(angle/2) = w)
    np.testing.assert_allclose(2 * np.arccos(np.clip(np.abs(q[:, 0]), -1, 1)),
                               np.abs((np.linalg.norm(r, axis=1) + np.pi) % (2 * np.pi) - np.pi), atol=1e-7)


@pytest.mark.parametrize("theta", [0.0, 1e-300, 1e-20, 1e-12, 1e-8, 1e-5, 1e-3])
def test_exp_and_log_near_zero_match_taylor_S1(theta):
    k = np.array([0.36, -0.48, 0.8])
    r = theta * k
    q = rot.rotvec_to_quat(r)
    taylor = np.concatenate([[1 - theta ** 2 / 8 + theta ** 4 / 384], (0.5 - theta ** 2 / 48) * r])
    np.testing.assert_allclose(q, taylor, rtol=0, atol=1e-15)
    np.testing.assert_allclose(q[1:] / max(theta, 1e-300), taylor[1:] / max(theta, 1e-300), rtol=1e-12)
    back = rot.quat_to_rotvec(q)
    np.testing.assert_allclose(back, r, rtol=1e-12, atol=0)


@pytest.mark.parametrize("delta", [0.0, 1e-12, 1e-8, 1e-4])
def test_log_near_pi(delta):
    k = np.array([2.0, -1.0, 2.0]) / 3
    theta = np.pi - delta
    q = rot.rotvec_to_quat(theta * k)
    np.testing.assert_allclose(rot.quat_to_rotvec(q), theta * k, atol=1e-14)
    # the matrix route must also survive the near-pi case (Shepperd pivot)
    q2 = rot.matrix_to_quat(rodrigues(theta * k))
    np.testing.assert_allclose(rot.quat_to_rotvec(q2), theta * k, atol=1e-7)
    np.testing.assert_allclose(rot.quat_to_matrix(q2), rodrigues(theta * k), atol=1e-14)


def test_log_inverts_exp_and_picks_w_nonnegative():
    r = RNG.normal(size=(200, 3))
    r *= (RNG.uniform(0, np.pi - 1e-3, 200) / np.linalg.norm(r, axis=1))[:, None]
    np.testing.assert_allclose(rot.quat_to_rotvec(rot.rotvec_to_quat(r)), r, atol=1e-13)
    np.testing.assert_allclose(rot.quat_to_rotvec(-rot.rotvec_to_quat(r)), r, atol=1e-13)


def test_matrix_to_quat_roundtrip_and_canonical():
    q = rot.quat_canonical(random_quats(500))
    np.testing.assert_allclose(rot.matrix_to_quat(rot.quat_to_matrix(q)), q, atol=1e-14)
    assert (rot.matrix_to_quat(rot.quat_to_matrix(q))[:, 0] >= 0).all()
    assert rot.matrix_to_quat(np.eye(3)[None].repeat(2, 0).reshape(1, 2, 3, 3)).shape == (1, 2, 4)


def test_quat_apply_matches_matrix():
    q, v = random_quats(30), RNG.normal(size=(30, 3))
    np.testing.assert_allclose(rot.quat_apply(q, v), np.einsum("nij,nj->ni", rot.quat_to_matrix(q), v), atol=1e-14)


def test_quat_normalize_zero_is_identity():
    np.testing.assert_array_equal(rot.quat_normalize(np.zeros((2, 4))), [[1, 0, 0, 0]] * 2)


def test_swing_twist_y_S4():
    q = random_quats(1000)
    sw, tw = rot.swing_twist_y(q)
    prod = rot.quat_mul(sw, tw)
    np.testing.assert_allclose(np.abs(np.sum(prod * q, axis=1)), 1, atol=1e-12)   # = ±q
    np.testing.assert_allclose(rot.quat_canonical(prod), rot.quat_canonical(q), atol=1e-12)
    np.testing.assert_allclose(sw[:, 2], 0, atol=1e-15)                             # swing has no Y part
    np.testing.assert_array_equal(tw[:, [1, 3]], 0)                                 # twist in span{1, j}
    assert (tw[:, 0] >= 0).all()
    # swing is the shortest arc taking Y to the posed Y axis: its axis is perpendicular to Y and
    # it maps Y to R(q) Y
    y = np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(rot.quat_apply(sw, y), rot.quat_apply(q, y), atol=1e-12)


def test_swing_twist_pure_cases_and_guard():
    tw_only = rot.rotvec_to_quat([0, 2.5, 0])
    sw, tw = rot.swing_twist_y(tw_only)
    np.testing.assert_allclose(sw, [1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(tw, tw_only, atol=1e-15)
    sw_only = rot.rotvec_to_quat([0.7, 0, -0.4])
    sw, tw = rot.swing_twist_y(sw_only)
    np.testing.assert_allclose(tw, [1, 0, 0, 0], atol=1e-15)
    # 180° swing about X: w = y = 0 -> identity twist, swing = q
    half = np.array([0.0, 1.0, 0.0, 0.0])
    sw, tw = rot.swing_twist_y(half)
    np.testing.assert_array_equal(tw, [1, 0, 0, 0])
    np.testing.assert_allclose(sw, half)
    # twist of negative-w input is taken after flipping: angle within (-pi, pi]
    q = -rot.rotvec_to_quat([0, 3.0, 0])
    _, tw = rot.swing_twist_y(q)
    np.testing.assert_allclose(rot.quat_to_rotvec(tw), [0, 3.0, 0], atol=1e-12)


def test_rotation_between_takes_a_onto_each_target_about_their_perpendicular():
    rng = np.random.default_rng(1)
    a = rng.normal(size=3)
    a /= np.linalg.norm(a)
    t = np.concatenate([rng.normal(size=(20, 3)), [-a, a]])
    t /= np.linalg.norm(t, axis=1)[:, None]
    G = rot.rotation_between(a, t)
    np.testing.assert_allclose(np.einsum("kij,j->ki", G, a), t, atol=1e-12)
    np.testing.assert_allclose(G @ np.swapaxes(G, 1, 2), np.broadcast_to(np.eye(3), G.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(G), 1.0, atol=1e-12)
    axis = np.cross(a, t[0])                                             # the perpendicular stays put
    np.testing.assert_allclose(G[0] @ axis, axis, atol=1e-12)
    np.testing.assert_allclose(G[-1], np.eye(3), atol=1e-12)


def test_rotation_between_handles_opposite_vectors_and_broadcasts():
    a = np.array([0.0, 0.0, 1.0])
    G = rot.rotation_between(a, -a)
    assert np.allclose(G @ a, -a) and np.isclose(np.linalg.det(G), 1.0)
    rng = np.random.default_rng(2)
    A = rng.normal(size=(2, 4, 3))
    A /= np.linalg.norm(A, axis=-1, keepdims=True)
    B = np.concatenate([-A[:, :1], rng.normal(size=(2, 3, 3))], axis=1)
    B /= np.linalg.norm(B, axis=-1, keepdims=True)
    G = rot.rotation_between(A, B)
    assert G.shape == (2, 4, 3, 3)
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", G, A), B, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(G), 1.0, atol=1e-12)
