"""Range-of-motion poses (sample_scenes.poses): limits, hinge directions, determinism, root motion."""
import numpy as np
import pytest

from articula.sample_scenes import subjects
from articula.sample_scenes.bone_roles import LIMITS, hinge_geometry, hinge_ranges, skeleton_roles
from articula.sample_scenes.poses import compose_swing_twist, rom_poses
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Poses
from articula.solver.geometry.rotations import swing_twist_y

EPS = 1e-9


@pytest.fixture(scope="module", params=["cmu_mb", "default"])
def skeleton(request):
    return subjects.make_subject(request.param).skeleton


def _angles(q):
    """Swing angle, swing axis (local) and signed twist angle about Y of quaternions (..., 4)."""
    swing, twist = swing_twist_y(q)
    sw_angle = 2 * np.arctan2(np.linalg.norm(swing[..., 1:], axis=-1), np.abs(swing[..., 0]))
    axis = swing[..., 1:] * np.sign(swing[..., :1]) / np.maximum(np.linalg.norm(swing[..., 1:], axis=-1,
                                                                                keepdims=True), 1e-300)
    tw_angle = 2 * np.arctan2(twist[..., 2], twist[..., 0])
    return sw_angle, axis, tw_angle


def test_poses_are_within_the_joint_limits(skeleton):
    poses = rom_poses(skeleton, 200, seed=5)
    poses.validate(skeleton.num_bones)
    roles = skeleton_roles(skeleton.names)
    swing, axis, twist = _angles(poses.rotations)
    hinge_axes, _ = hinge_geometry(skeleton, roles)
    ranges = hinge_ranges(skeleton, roles)
    for b, role in enumerate(roles):
        lim = LIMITS[role]
        assert np.abs(twist[:, b]).max() <= np.radians(lim.twist) + EPS, role
        if lim.hinge is None:
            assert swing[:, b].max() <= np.radians(lim.cone) + EPS, role
        else:
            lo, hi = ranges[b]
            signed = swing[:, b] * np.sign(axis[:, b] @ hinge_axes[b])
            assert signed.min() >= lo - EPS and signed.max() <= hi + EPS, role
            moving = swing[:, b] > 1e-6
            assert np.allclose(np.abs(axis[moving, b] @ hinge_axes[b]), 1), role
        if lim.cone or lim.hinge:          # the limits are used, not just respected
            assert swing[:, b].max() > 0.6 * max(np.radians(lim.cone), np.nan_to_num(ranges[b, 1])), role


def _directions(skeleton, Rm):
    d = np.einsum("bij,bj->bi", Rm, skeleton.tails - skeleton.heads)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_hinges_flex_anatomically(skeleton):
    """Flexing knees and elbows to the top of their range: the segments bend to the anatomical angle
    (145 deg elbow, 135 deg knee between the segments), the shin swings backward (+Y), the forearm
    comes forward/up, and the hinge plane contains both segments."""
    roles = skeleton_roles(skeleton.names)
    axes, rest = hinge_geometry(skeleton, roles)
    ranges = hinge_ranges(skeleton, roles)
    hinges = [b for b, role in enumerate(roles) if role in ("knee", "forearm")]
    assert len(hinges) >= 4
    rot = np.zeros((1, skeleton.num_bones, 4))
    rot[..., 0] = 1
    for b in hinges:
        rot[0, b] = compose_swing_twist(ranges[b, 1] * axes[b], np.zeros(()))
    Rm, tm = forward_kinematics(skeleton, Poses(rot, np.zeros((1, 3)), np.ones(1)))
    before = _directions(skeleton, np.tile(np.eye(3), (skeleton.num_bones, 1, 1)))
    after = _directions(skeleton, Rm[0])
    for b in hinges:
        p = skeleton.parents[b]
        angle = np.degrees(np.arccos(np.clip(after[p] @ after[b], -1, 1)))
        if roles[b] == "knee":            # straight at rest: bends backward, about the flex-direction axis
            assert angle == pytest.approx(LIMITS["knee"].hinge[1], abs=3), skeleton.names[b]
            assert after[b][1] > 0.5
        else:                             # bent at rest: exactly in the plane of the two bones
            assert angle == pytest.approx(LIMITS["forearm"].hinge[1], abs=1e-6), skeleton.names[b]
            assert abs(np.linalg.det(np.stack([before[p], before[b], after[b]]))) < 1e-9
            assert after[b][2] > before[b][2] + 0.5            # the hand comes up
    assert np.degrees(rest[[b for b in hinges if roles[b] == "forearm"]]).min() > 20   # A-pose elbows


def test_determinism(skeleton):
    a, b = rom_poses(skeleton, 10, seed=1), rom_poses(skeleton, 10, seed=1)
    c = rom_poses(skeleton, 10, seed=2)
    assert np.array_equal(a.rotations, b.rotations)
    assert np.abs(a.rotations - c.rotations).max() > 0.1


def test_key_every_interpolates_smoothly(skeleton):
    rough = rom_poses(skeleton, 40, seed=3)
    smooth = rom_poses(skeleton, 40, seed=3, key_every=8)
    step = lambda p: np.abs(np.diff(p.rotations, axis=0)).max(axis=(1, 2)).mean()
    assert step(smooth) < 0.3 * step(rough)


def test_root_motion(skeleton):
    poses = rom_poses(skeleton, 30, seed=4, root_yaw=90, root_shift=0.5)
    assert np.abs(poses.translations[:, :2]).max() <= 0.5 and np.all(poses.translations[:, 2] == 0)
    assert np.abs(poses.translations).max() > 0.2
    Rm, tm = forward_kinematics(skeleton, poses)
    up = Rm[:, 0] @ np.array([0, 0, 1.0])
    assert np.allclose(up, [0, 0, 1])                         # yaw only: the root stays upright
    yaw = np.degrees(np.arctan2(Rm[:, 0, 1, 0], Rm[:, 0, 0, 0]))
    assert np.abs(yaw).max() <= 90 + 1e-6 and np.abs(yaw).max() > 30
    head = np.einsum("nij,j->ni", Rm[:, 0], skeleton.heads[0]) + tm[:, 0]
    assert np.allclose(head, skeleton.heads[0] + poses.translations)


def test_role_amplitude_scales_one_role(skeleton):
    full = rom_poses(skeleton, 12, seed=6, amplitude=0.8)
    part = rom_poses(skeleton, 12, seed=6, amplitude=0.8, role_amplitude={"upper_arm": 0.5, "knee": 0.0})
    roles = np.array(skeleton_roles(skeleton.names))
    arm, knee = roles == "upper_arm", roles == "knee"
    sw_full, _, tw_full = _angles(full.rotations)
    sw_part, _, tw_part = _angles(part.rotations)
    np.testing.assert_allclose(sw_part[:, arm], 0.5 * sw_full[:, arm], atol=1e-9)    # the same draws, scaled
    np.testing.assert_allclose(tw_part[:, arm], 0.5 * tw_full[:, arm], atol=1e-9)
    assert np.abs(sw_part[:, knee]).max() < 1e-9 and np.abs(sw_full[:, knee]).max() > 0.1
    rest = ~(arm | knee)
    np.testing.assert_allclose(part.rotations[:, rest], full.rotations[:, rest], atol=1e-12)
    with pytest.raises(ArticulaInputError, match="role_amplitude: 'elbow'"):
        rom_poses(skeleton, 3, role_amplitude={"elbow": 0.5})


@pytest.mark.parametrize("kwargs, word", [(dict(n=0), "positive"), (dict(n=3, amplitude=2), "amplitude"),
                                          (dict(n=3, key_every=0), "key_every"), (dict(n=3, root_yaw=200), "root_yaw"),
                                          (dict(n=3, root_shift=-1), "root_shift")])
def test_bad_parameters(skeleton, kwargs, word):
    with pytest.raises(ArticulaInputError, match=word):
        rom_poses(skeleton, **kwargs)
