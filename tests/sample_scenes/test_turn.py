"""The turn motion (sample_scenes.turn): yaw range and smoothness, limbs moving, feet on the floor,
determinism, every rig, the samples command."""
import numpy as np
import pytest

from articula.sample_scenes import registered, turn
from articula.sample_scenes.mpfb_rig import RIGS
from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Poses

N = 64


@pytest.fixture(scope="module", params=RIGS)
def sequence(request):
    """(rig, subject, posed vertices (N, V, 3) hybrid skin, gt) of a subject turning by +-40 deg."""
    rig = request.param
    posed, _, gt = registered.posed_sequence(rig, None, N, "turn", "hybrid", seed=3, subject_seed=2)
    return rig, make_subject(rig, None, 2), posed, gt


def _root_yaw(subject, gt):
    """World yaw (degrees) of the root bone per frame, and its up axis (N, 3)."""
    poses = Poses(gt["pose_rotations"], gt["pose_translations"], gt["pose_scales"])
    Rm, _ = forward_kinematics(subject.skeleton, poses)
    return np.degrees(np.arctan2(Rm[:, 0, 1, 0], Rm[:, 0, 0, 0])), Rm[:, 0] @ np.array([0, 0, 1.0])


def test_yaw_oscillates_between_the_limits_and_is_smooth(sequence):
    rig, subject, _, gt = sequence
    yaw, up = _root_yaw(subject, gt)
    assert np.allclose(up, [0, 0, 1], atol=1e-9), rig            # turning about the vertical only
    assert yaw[0] == pytest.approx(0, abs=1e-9)
    assert np.abs(yaw).max() <= 40 + 1e-6
    assert yaw.max() > 39.5 and yaw.min() < -39.5                 # reaches both sides ...
    assert 10 <= np.argmax(yaw) <= 20 and 40 <= np.argmin(yaw) <= 50   # ... left first, one cycle per 60 frames
    assert np.abs(np.diff(yaw)).max() <= 40 * 2 * np.pi / 60 + 1e-6   # the sine's largest step, 4.2 deg
    np.testing.assert_allclose(yaw, np.degrees(turn.turn_yaw(N)), atol=1e-6)


def test_limbs_move_smoothly_and_the_feet_stay_on_the_floor(sequence):
    rig, subject, posed, gt = sequence
    joints = gt["posed_heads"][:, gt["major_joint_bones"]]
    step = np.linalg.norm(np.diff(joints, axis=0), axis=2)          # (N-1, 14) metres per frame
    assert step.max() < 0.12, rig                                   # < 3.6 m/s at 30 fps
    wrists = joints[:, 4:6]
    travel = np.linalg.norm(wrists - wrists[:1], axis=2).max()
    assert travel > 0.3, rig                                       # the arms really move
    rest_wrist_z = subject.skeleton.heads[gt["major_joint_bones"][4], 2]
    assert wrists[..., 2].max() > rest_wrist_z + 0.2, rig          # and rise
    lowest = posed[..., 2].min(axis=1)
    assert np.abs(lowest).max() < 0.005, rig                        # one foot on the floor (z = 0) in every frame
    feet = turn.foot_vertices(subject)
    left, right = feet[subject.vertices[feet, 0] > 0], feet[subject.vertices[feet, 0] < 0]
    assert min(len(left), len(right)) > 500
    lift = np.maximum(posed[:, left, 2].min(1), posed[:, right, 2].min(1))
    assert lift.max() < 0.15, rig                                   # the other foot lifts a little at most
    head = joints[:, 13, 2]
    assert head.min() > 0.85 * subject.skeleton.heads[gt["major_joint_bones"][13], 2]   # roughly upright


def test_turn_is_reproducible_and_seeded():
    subject = make_subject("cmu_mb")
    a, b = turn.turn_poses(subject, 20, seed=1), turn.turn_poses(subject, 20, seed=1)
    c = turn.turn_poses(subject, 20, seed=2)
    assert np.array_equal(a.rotations, b.rotations) and np.array_equal(a.translations, b.translations)
    assert np.abs(a.rotations[:, 1:] - c.rotations[:, 1:]).max() > 0.05
    np.testing.assert_allclose(a.rotations[:, 0], c.rotations[:, 0], atol=1e-12)   # the same turn
    small = turn.turn_poses(subject, 20, seed=1, turn_degrees=10, period=40)
    yaw = 2 * np.degrees(np.arctan2(np.linalg.norm(small.rotations[:, 0, 1:], axis=1), small.rotations[:, 0, 0]))
    assert yaw.max() == pytest.approx(10, abs=0.1) and np.argmax(yaw) in (10, 30)


@pytest.mark.parametrize("kwargs, word", [(dict(turn_degrees=200), "turn_degrees"), (dict(period=1), "turn_period"),
                                          (dict(root_yaw=30), "root_yaw"), (dict(amplitude=0), "amplitude")])
def test_bad_parameters(kwargs, word):
    with pytest.raises(ArticulaInputError, match=word):
        turn.turn_poses(make_subject("cmu_mb"), 5, **kwargs)


def test_samples_command_with_turn(tmp_path, capsys):
    from articula.addon.cli.main import main as cli_main
    out = tmp_path / "seq"
    code = cli_main(["samples", "registered", "--rig", "mixamo", "--poses", "16", "--motion", "turn",
                     "--turn-degrees", "25", "--format", "ply", "--out", str(out)])
    assert code == 0 and "motion turn" in capsys.readouterr().out
    g = np.load(out / "ground_truth.npz")
    assert str(g["motion"]) == "turn" and g["pose_rotations"].shape[0] == 16
    q = g["pose_rotations"][:, 0]
    yaw = 2 * np.degrees(np.arctan2(np.linalg.norm(q[:, 1:], axis=1), np.abs(q[:, 0])))
    assert yaw.max() == pytest.approx(25, abs=0.5)
    code = cli_main(["samples", "registered", "--motion", "turn", "--root-yaw", "10", "--out", str(tmp_path / "x")])
    assert code == 2 and "root_yaw" in capsys.readouterr().err
