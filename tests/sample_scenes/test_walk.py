"""Walk cycle (sample_scenes.walk, sample_scenes.fcurves): curve evaluation, IK reach, ground contact,
gait, retargeting consistency, limits."""
import numpy as np
import pytest

from articula.sample_scenes import fcurves, subjects, walk
from articula.sample_scenes.bone_roles import LIMITS, skeleton_roles
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.geometry.rotations import rotvec_to_matrix
from articula.solver.rig.skinning import lbs


def test_bezier_with_third_handles_on_the_chord_is_linear():
    frames, values = np.array([0.0, 6.0, 9.0]), np.array([1.0, 4.0, -2.0])
    handles = np.zeros((3, 2, 2))
    for k in range(3):                     # handles a third of the way to the neighbours, on the chord
        for side, other in ((0, k - 1), (1, k + 1)):
            if 0 <= other < 3:
                handles[k, side] = [frames[k] + (frames[other] - frames[k]) / 3,
                                    values[k] + (values[other] - values[k]) / 3]
    curve = fcurves.FCurve(frames, values, handles, ("BEZIER",) * 3)
    x = np.linspace(-2, 11, 53)
    assert np.allclose(curve(x), np.interp(x, frames, values), atol=1e-9)
    assert np.allclose(curve(frames), values)


def test_bezier_matches_the_cubic_it_encodes():
    """Handles of a cubic's Bezier form: the curve must reproduce the cubic (x(t) linear in t)."""
    f = lambda x: 0.1 * x ** 3 - x ** 2 + 2 * x + 1
    df = lambda x: 0.3 * x ** 2 - 2 * x + 2
    x0, x1 = 2.0, 5.0
    h = (x1 - x0) / 3
    handles = np.array([[[x0 - h, 0], [x0 + h, f(x0) + h * df(x0)]],
                        [[x1 - h, f(x1) - h * df(x1)], [x1 + h, 0]]])
    curve = fcurves.FCurve(np.array([x0, x1]), np.array([f(x0), f(x1)]), handles, ("BEZIER", "BEZIER"))
    x = np.linspace(x0, x1, 31)
    assert np.allclose(curve(x), f(x), atol=1e-9)


def test_euler_xyz_is_z_after_y_after_x():
    e = np.array([0.3, -0.7, 1.1])
    expect = rotvec_to_matrix([0, 0, e[2]]) @ rotvec_to_matrix([0, e[1], 0]) @ rotvec_to_matrix([e[0], 0, 0])
    assert np.allclose(fcurves.euler_xyz_to_matrix(e), expect)


@pytest.fixture(scope="module", params=["cmu_mb", "mixamo"])
def walking(request):
    subject = subjects.make_subject(request.param, "female")
    poses = walk.walk_poses(subject, 40, seed=3)
    Rm, tm = forward_kinematics(subject.skeleton, poses)
    return subject, poses, Rm, tm


def _heads(subject, Rm, tm, bones):
    return np.einsum("nbij,bj->nbi", Rm[:, bones], subject.skeleton.heads[bones]) + tm[:, bones]


def test_walk_poses_are_valid_and_deterministic(walking):
    subject, poses, _, _ = walking
    poses.validate(subject.skeleton.num_bones)
    again = walk.walk_poses(subject, 40, seed=3)
    other = walk.walk_poses(subject, 40, seed=4)
    assert np.array_equal(again.rotations, poses.rotations)
    assert np.abs(other.rotations - poses.rotations).max() > 0.05


def test_feet_reach_the_ik_targets_and_touch_the_ground(walking):
    subject, poses, Rm, tm = walking
    rt = walk._Retarget(subject.skeleton, walk._source_skeleton(subject))
    rng = np.random.default_rng(3)                       # the same phase as walk_poses(seed=3)
    f = rng.uniform(0, walk.CYCLE_FRAMES) + np.arange(40)
    cycles, frames = np.floor(f / walk.CYCLE_FRAMES), np.mod(f, walk.CYCLE_FRAMES)
    down = walk.ground_offset(rt, walk._scale(rt))
    for side in "LR":
        ankle = rt.first("ankle", side)
        target = walk._foot_targets(rt, frames, cycles, walk._scale(rt), side) - [0, 0, down]
        assert np.abs(_heads(subject, Rm, tm, [ankle])[:, 0] - target).max() < 0.01
    posed = lbs(subject.vertices, subject.lbs_weights, Rm, tm)
    lowest = posed[..., 2].min(axis=1)
    # the file's foot pitch lets toes/heels dip or hover by a few cm (documented in walk.py)
    assert np.abs(lowest).max() < 0.05 and np.abs(lowest).mean() < 0.025 and np.abs(lowest).min() < 0.005


def test_gait_alternates_and_advances(walking):
    subject, poses, Rm, tm = walking
    roles = skeleton_roles(subject.skeleton.names)
    ankles = [b for b, r in enumerate(roles) if r == "ankle"]
    y = _heads(subject, Rm, tm, ankles)[..., 1] - _heads(subject, Rm, tm, [0])[..., 1]
    assert np.corrcoef(y[:, 0], y[:, 1])[0, 1] < -0.5          # one foot forward while the other is back
    travel = _heads(subject, Rm, tm, [0])[0, 0] - _heads(subject, Rm, tm, [0])[-1, 0]
    assert 0.6 < travel[1] * 40 / 39 < 1.0 and abs(travel[0]) < 0.05   # ~0.78 m per cycle, forwards = -Y


def test_knees_and_elbows_stay_in_their_anatomical_range(walking):
    subject, poses, Rm, tm = walking
    sk = subject.skeleton
    roles = skeleton_roles(sk.names)
    d = np.einsum("nbij,bj->nbi", Rm, sk.tails - sk.heads)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    for b, role in enumerate(roles):
        if role in ("knee", "forearm"):
            angle = np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", d[:, sk.parents[b]], d[:, b]), -1, 1)))
            assert angle.max() < LIMITS[role].hinge[1] and angle.max() > 5, sk.names[b]


def test_rigs_walk_the_same_way():
    a, b = subjects.make_subject("cmu_mb"), subjects.make_subject("game_engine")
    pa, pb = walk.walk_poses(a, 10, seed=1), walk.walk_poses(b, 10, seed=1)
    ra, rb = forward_kinematics(a.skeleton, pa), forward_kinematics(b.skeleton, pb)
    for side in "LR":
        ia = [i for i, n in enumerate(a.skeleton.names) if n == f"Foot.{side}"]
        ib = [i for i, n in enumerate(b.skeleton.names) if n == f"foot.{side}"]
        assert np.abs(_heads(a, *ra, ia) - _heads(b, *rb, ib)).max() < 0.01


def test_heading_and_bad_parameters():
    subject = subjects.make_subject("cmu_mb")
    turned = walk.walk_poses(subject, 2, seed=0, root_yaw=180)
    Rm, _ = forward_kinematics(subject.skeleton, turned)
    straight = forward_kinematics(subject.skeleton, walk.walk_poses(subject, 2, seed=0))[0]
    assert np.abs(Rm[:, 0] - straight[:, 0]).max() > 0.05
    for kwargs, word in ((dict(n=0), "positive"), (dict(n=2, step=0), "step"), (dict(n=2, root_yaw=-1), "root_yaw")):
        with pytest.raises(ArticulaInputError, match=word):
            walk.walk_poses(subject, **kwargs)
