"""Forward kinematics (dissertation (model-adaptive mocap) §8.1 S2, S3, S13, S14) against closed forms and
homogeneous matrices."""
import numpy as np

from articula.solver.rig import kinematics
from articula.sample_scenes import synthetic
from articula.solver.geometry import rotations as rot
from articula.solver.rig.model import Poses, Skeleton, frames_from_bones

RNG = np.random.default_rng(3)


def chain3():
    heads = np.array([[0, 0, 0], [0, 1, 0], [0.5, 2, 0.2], [1, 2.5, 0.5]], dtype=float)
    tails = np.array([[0, 1, 0], [0.5, 2, 0.2], [1, 2.5, 0.5], [1, 3, 1]], dtype=float)
    return Skeleton(list("abcd"), [-1, 0, 1, 2], heads, tails, frames_from_bones(heads, tails))


def homogeneous_reference(sk, poses):
    """Independent reference: 4x4 matrices T(h) Rot T(-h) composed root-first."""
    N, B = poses.rotations.shape[:2]
    out = np.zeros((N, B, 4, 4))
    for n in range(N):
        for b in range(B):
            F = sk.frames[b]
            R = F @ rot.quat_to_matrix(poses.rotations[n, b]) @ F.T
            h = sk.heads[b]
            M = np.eye(4)
            M[:3, :3] = R
            M[:3, 3] = h - R @ h
            if b == 0:
                S = np.diag([poses.scales[n]] * 3 + [1.0])
                T = np.eye(4)
                T[:3, 3] = poses.translations[n] + h
                Tm = np.eye(4)
                Tm[:3, 3] = -h
                R4 = np.eye(4)
                R4[:3, :3] = R
                out[n, b] = T @ S @ R4 @ Tm
            else:
                out[n, b] = out[n, sk.parents[b]] @ M
    return out


def test_frames_from_bones_S2():
    sk = synthetic.human_skeleton()
    sk.validate()
    y = sk.frames[:, :, 1]
    d = sk.tails - sk.heads
    cos = np.sum(y * d, axis=1) / np.linalg.norm(d, axis=1)
    assert (cos > 1 - 1e-12).all()
    np.testing.assert_allclose(np.linalg.det(sk.frames), 1, atol=1e-12)


def test_local_twist_fixes_world_axis_S3():
    sk = chain3()
    b = 2
    R = kinematics.world_rotations(sk, rot.rotvec_to_quat(np.array([[[0, 0.9, 0]] * 4])))[0, b]
    axis = sk.frames[b][:, 1]
    np.testing.assert_allclose(R @ axis, axis, atol=1e-14)
    x = sk.heads[b] + 0.3 * (sk.tails[b] - sk.heads[b])
    Rm, tm = kinematics.chain_from_world(sk, np.broadcast_to(np.eye(3), (1, 4, 3, 3)).copy(), np.zeros((1, 3)),
                                         np.ones(1))
    np.testing.assert_allclose(Rm[0, b] @ x + tm[0, b], x)


def test_closed_form_K3_S13():
    """Eq. 3.10-3.12: K_3(v) = R3R2R1 v + R3R2(1−R1)t1 + R3(1−R2)t2 + (1−R3)t3, index 1 nearest the vertex."""
    sk = chain3()
    q = rot.quat_normalize(RNG.normal(size=(1, 4, 4)))
    q[0, 0] = [1, 0, 0, 0]
    poses = Poses(q, np.zeros((1, 3)), np.ones(1))
    Rw = kinematics.world_rotations(sk, q)[0]
    R3, R2, R1 = Rw[1], Rw[2], Rw[3]               # joint of part d is nearest the vertex
    t3, t2, t1 = sk.heads[1], sk.heads[2], sk.heads[3]
    I = np.eye(3)
    v = RNG.normal(size=3)
    closed = R3 @ R2 @ R1 @ v + R3 @ R2 @ (I - R1) @ t1 + R3 @ (I - R2) @ t2 + (I - R3) @ t3
    Rm, tm = kinematics.forward_kinematics(sk, poses)
    np.testing.assert_allclose(Rm[0, 3] @ v + tm[0, 3], closed, atol=1e-12)


def test_matches_homogeneous_reference_with_similarity():
    sk = synthetic.human_skeleton()
    poses = synthetic.random_poses(4, sk.num_bones, seed=5)
    Rm, tm = kinematics.forward_kinematics(sk, poses)
    ref = homogeneous_reference(sk, poses)
    np.testing.assert_allclose(Rm, ref[..., :3, :3], atol=1e-13)
    np.testing.assert_allclose(tm, ref[..., :3, 3], atol=1e-13)


def test_identity_pose_is_identity_map_S14():
    sk = synthetic.human_skeleton()
    Rm, tm = kinematics.forward_kinematics(sk, Poses.identity(2, sk.num_bones))
    np.testing.assert_allclose(Rm, np.broadcast_to(np.eye(3), Rm.shape), atol=1e-15)
    np.testing.assert_allclose(tm, 0, atol=1e-15)


def test_joint_centres_follow_parent_chain():
    """The head of every bone is moved by its own map exactly as by its parent's (joints stay connected)."""
    sk = synthetic.human_skeleton()
    poses = synthetic.random_poses(3, sk.num_bones, seed=9)
    Rm, tm = kinematics.forward_kinematics(sk, poses)
    for b in range(1, sk.num_bones):
        p = sk.parents[b]
        np.testing.assert_allclose(Rm[:, b] @ sk.heads[b] + tm[:, b], Rm[:, p] @ sk.heads[b] + tm[:, p], atol=1e-13)
