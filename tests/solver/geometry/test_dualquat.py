"""Dual quaternions and DLB (spec §8.1 S5-S8) against closed forms."""
import numpy as np

from articula.solver.geometry import dualquat as dq
from articula.solver.geometry import rotations as rot

RNG = np.random.default_rng(11)


def test_rotation_about_centre_S5():
    q = rot.quat_normalize(RNG.normal(size=(50, 4)))
    c = RNG.normal(size=(50, 3))
    v = RNG.normal(size=(50, 3))
    d = dq.dq_rotation_about(q, c)
    np.testing.assert_allclose(np.linalg.norm(d[:, :4], axis=1), 1, atol=1e-15)     # |q0| = 1
    np.testing.assert_allclose(np.sum(d[:, :4] * d[:, 4:], axis=1), 0, atol=1e-14)   # <q0, qe> = 0
    np.testing.assert_allclose(dq.dq_apply(d, c), c, atol=1e-13)
    R = rot.quat_to_matrix(q)
    np.testing.assert_allclose(dq.dq_apply(d, v), np.einsum("nij,nj->ni", R, v - c) + c, atol=1e-13)


def test_dual_part_equals_half_commutator():
    """qe = ½ ((0,c)·q − q·(0,c)) (spec §1.4) computed with the Hamilton product."""
    q = rot.quat_normalize(RNG.normal(size=(20, 4)))
    c = RNG.normal(size=(20, 3))
    cq = np.concatenate([np.zeros((20, 1)), c], axis=1)
    ref = 0.5 * (rot.quat_mul(cq, q) - rot.quat_mul(q, cq))
    np.testing.assert_allclose(dq.dq_rotation_about(q, c)[:, 4:], ref, atol=1e-15)


def test_rigid_roundtrip_and_normalising_apply():
    R = rot.quat_to_matrix(rot.quat_normalize(RNG.normal(size=(30, 4))))
    t = RNG.normal(size=(30, 3))
    v = RNG.normal(size=(30, 3))
    d = dq.dq_from_rigid(R, t)
    np.testing.assert_allclose(dq.dq_apply(d, v), np.einsum("nij,nj->ni", R, v) + t, atol=1e-13)
    np.testing.assert_allclose(dq.dq_apply(3.7 * d, v), np.einsum("nij,nj->ni", R, v) + t, atol=1e-13)
    R2, t2 = dq.dq_to_rigid(-2 * d)
    np.testing.assert_allclose(R2, R, atol=1e-14)
    np.testing.assert_allclose(t2, t, atol=1e-13)


def test_dlb_single_joint_full_weight_is_rigid_S6():
    q = rot.quat_normalize(RNG.normal(size=(10, 1, 4)))
    c = RNG.normal(size=(10, 1, 3))
    d = dq.dq_rotation_about(q, c)
    v = RNG.normal(size=(10, 3))
    out = dq.dq_apply(dq.dlb(np.ones((10, 1)), d), v)
    np.testing.assert_allclose(out, dq.dq_apply(d[:, 0], v), atol=1e-13)


def test_dlb_coaxial_half_weight_gives_half_angle_S6():
    c = np.array([0.3, -1.0, 2.0])
    for pivot in ("identity", "max"):
        d = dq.dq_rotation_about(rot.rotvec_to_quat([0, 0, np.pi - 1e-9]), c)[None]
        blended = dq.dlb(np.array([0.5]), d, pivot=pivot)
        R, t = dq.dq_to_rigid(blended)
        np.testing.assert_allclose(R, rot.rotvec_to_matrix([0, 0, (np.pi - 1e-9) / 2]), atol=1e-12)
        np.testing.assert_allclose(R @ c + t, c, atol=1e-12)                    # centre fixed


def test_dlb_output_is_rigid_S6():
    K = 3
    q = rot.quat_normalize(RNG.normal(size=(200, K, 4)))
    c = RNG.normal(size=(200, K, 3))
    w = RNG.dirichlet(np.ones(K + 1), size=200)[:, :K]
    b = dq.dlb(w, dq.dq_rotation_about(q, c))
    R, t = dq.dq_to_rigid(b)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(R), 1, atol=1e-13)
    x, y = RNG.normal(size=(2, 200, 3))
    dist = np.linalg.norm(dq.dq_apply(b, x) - dq.dq_apply(b, y), axis=1)
    np.testing.assert_allclose(dist, np.linalg.norm(x - y, axis=1), rtol=1e-12)


def test_dlb_zero_weights_is_identity_S7():
    d = dq.dq_rotation_about(rot.quat_normalize(RNG.normal(size=(5, 2, 4))), RNG.normal(size=(5, 2, 3)))
    v = RNG.normal(size=(5, 3))
    np.testing.assert_array_equal(dq.dq_apply(dq.dlb(np.zeros((5, 2)), d), v), v)


def test_dlb_neutral_remainder_matches_explicit_identity_joint_S7():
    d = dq.dq_rotation_about(rot.quat_canonical(rot.quat_normalize(RNG.normal(size=(5, 2, 4)))),
                             RNG.normal(size=(5, 2, 3)))
    w = np.array([[0.2, 0.3]] * 5)
    with_id = np.concatenate([d, np.broadcast_to(dq.IDENTITY, (5, 1, 8))], axis=1)
    v = RNG.normal(size=(5, 3))
    np.testing.assert_allclose(dq.dq_apply(dq.dlb(w, d), v),
                               dq.dq_apply(dq.dlb(np.array([[0.2, 0.3, 0.5]] * 5), with_id), v), atol=1e-14)


def test_dlb_antipodal_invariance_S8():
    K = 4
    q = rot.quat_normalize(RNG.normal(size=(100, K, 4)))
    d = dq.dq_rotation_about(q, RNG.normal(size=(100, K, 3)))
    w = RNG.dirichlet(np.ones(K + 1), size=100)[:, :K]
    v = RNG.normal(size=(100, 3))
    signs = RNG.choice([-1.0, 1.0], size=(100, K, 1))
    for pivot in ("identity", "max"):
        ref = dq.dq_apply(dq.dlb(w, d, pivot), v)
        np.testing.assert_allclose(dq.dq_apply(dq.dlb(w, signs * d, pivot), v), ref, atol=1e-12)
    # without alignment the result would differ: the test can fail
    naive = np.einsum("nk,nki->ni", w, signs * d) + (1 - w.sum(1))[:, None] * dq.IDENTITY
    assert np.abs(dq.dq_apply(naive, v) - dq.dq_apply(dq.dlb(w, d), v)).max() > 1e-3
