"""The reach motion (sample_scenes.reach): arms raised above the shoulders and down by the sides, the trunk
bending and twisting by the drawn key rotation, smooth, deterministic, every rig."""
import numpy as np
import pytest

from articula.sample_scenes import reach
from articula.sample_scenes.bone_roles import skeleton_roles
from articula.sample_scenes.mpfb_rig import RIGS
from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.rotations import quat_to_matrix
from articula.solver.rig.kinematics import forward_kinematics, world_rotations

N, KEY = 41, 10


@pytest.fixture(scope="module", params=RIGS)
def motion(request):
    subject = make_subject(request.param, "male", 2)
    return subject, reach.reach_poses(subject, N, seed=5, key_every=KEY)


def _arm_elevations(subject, poses):
    """(N, 2) degrees above the horizontal of the two upper arms, posed."""
    sk = subject.skeleton
    arms = [b for b, r in enumerate(skeleton_roles(sk.names)) if r == "upper_arm"]
    Rm, tm = forward_kinematics(sk, poses)
    d = np.einsum("nbij,bj->nbi", Rm[:, arms], sk.tails[arms] - sk.heads[arms])
    return np.degrees(np.arcsin(d[..., 2] / np.linalg.norm(d, axis=-1)))


def test_arms_rise_above_the_shoulders_and_fall_by_the_sides(motion):
    subject, poses = motion
    el = _arm_elevations(subject, poses)
    assert el.max() > 45 and el.min() < -30, subject.rig


def test_the_trunk_turns_by_the_drawn_key_rotation(motion):
    subject, poses = motion
    sk = subject.skeleton
    roles = skeleton_roles(sk.names)
    trunk = reach.trunk_bones(sk, roles)
    assert 3 <= len(trunk) <= 5 and all(roles[b] == "spine" for b in trunk)
    rng = np.random.default_rng([5, 1])
    keys = reach.trunk_rotvecs(rng, (N - 1) // KEY + 2)
    # at a key frame the spine bones' world rotations without their own random part compose to the key's
    R = world_rotations(sk, poses.rotations[KEY:KEY + 1])[0]
    own = world_rotations(sk, reach.rom_poses(sk, N, seed=5, key_every=KEY, root_yaw=45.0, root_shift=0.1,
                                              role_amplitude={r: reach.REACH_AMPLITUDE.get(r, 0.3)
                                                              for r in set(roles)}).rotations[KEY:KEY + 1])[0]
    total = np.eye(3)
    for b in sorted(trunk):
        total = total @ R[b] @ own[b].T
    angle = np.linalg.norm(keys[1])
    expected = quat_to_matrix(np.r_[np.cos(angle / 2), np.sin(angle / 2) * keys[1] / angle])
    assert np.allclose(total, expected, atol=1e-9)
    assert np.degrees(np.abs(keys[:, :2]).max()) > 30                     # a real bend among the keys


def test_smooth_and_deterministic(motion):
    subject, poses = motion
    el = _arm_elevations(subject, poses)
    assert np.abs(np.diff(el, axis=0)).max() < 25                         # degrees per frame
    again = reach.reach_poses(subject, N, seed=5, key_every=KEY)
    assert np.array_equal(again.rotations, poses.rotations)
    assert not np.array_equal(reach.reach_poses(subject, N, seed=6, key_every=KEY).rotations, poses.rotations)


def test_bad_settings_are_refused():
    subject = make_subject("cmu_mb")
    with pytest.raises(ArticulaInputError, match="key_every"):
        reach.reach_poses(subject, 10, key_every=0)
    with pytest.raises(ArticulaInputError, match="turn_degrees"):
        reach.reach_poses(subject, 10, turn_degrees=200)
