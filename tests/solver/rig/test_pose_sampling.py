"""The rig's seeded pose sampler (solver.rig.pose_sampling) against an independent construction:
rotation matrices of the swing and twist rotation vectors (Rodrigues), and its documented ranges."""
import numpy as np

from articula.solver.geometry.rotations import quat_to_matrix, rotvec_to_matrix, swing_twist_y
from articula.solver.rig import pose_sampling


def _reference_matrices(seed, n, bones, max_twist_deg, max_swing_deg):
    """(n, bones, 3, 3) swing @ twist from the sampler's draws (same order), built with rotation vectors."""
    rng = np.random.default_rng(seed)
    twist = np.radians(rng.uniform(-max_twist_deg, max_twist_deg, (n, bones)))
    swing = np.radians(rng.uniform(0, max_swing_deg, (n, bones)))
    phi = rng.uniform(0, 2 * np.pi, (n, bones))
    axis = np.stack([np.cos(phi), np.zeros_like(phi), np.sin(phi)], -1)
    y = np.array([0.0, 1.0, 0.0])
    return rotvec_to_matrix(swing[..., None] * axis) @ rotvec_to_matrix(twist[..., None] * y)


def test_joint_rotations_are_swing_after_twist_with_the_drawn_angles():
    poses = pose_sampling.random_poses(50, 6, seed=3, max_twist_deg=90.0, max_swing_deg=60.0)
    ref = _reference_matrices(3, 50, 6, 90.0, 60.0)
    np.testing.assert_allclose(quat_to_matrix(poses.rotations)[:, 1:], ref[:, 1:], atol=1e-12)


def test_ranges_of_twist_swing_root_translation_and_scale():
    poses = pose_sampling.random_poses(400, 5, seed=1, max_twist_deg=45.0, max_swing_deg=30.0)
    q = poses.rotations
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    swing, twist = swing_twist_y(q[:, 1:])
    twist_deg = np.degrees(2 * np.arctan2(np.abs(twist[..., 2]), twist[..., 0]))
    swing_deg = np.degrees(2 * np.arccos(np.clip(np.abs(swing[..., 0]), 0, 1)))
    assert twist_deg.max() <= 45.0 + 1e-9 and twist_deg.max() > 40.0
    assert swing_deg.max() <= 30.0 + 1e-9 and swing_deg.max() > 25.0
    assert np.abs(q[:, 0, 2]).max() > 0.5                     # the root is not limited to the joint range
    assert np.abs(poses.translations).max() <= 0.5 and poses.scales.min() >= 0.7 and poses.scales.max() <= 1.4


def test_seeded():
    a, b = pose_sampling.random_poses(4, 3, seed=7), pose_sampling.random_poses(4, 3, seed=7)
    assert np.array_equal(a.rotations, b.rotations) and np.array_equal(a.scales, b.scales)
    assert not np.array_equal(a.rotations, pose_sampling.random_poses(4, 3, seed=8).rotations)
