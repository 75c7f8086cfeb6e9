"""Starts that put a lost fit's trunk right (solver.tracking.trunk_starts), on a MakeHuman subject's true
pose made wrong in the ways a search ends: hips turned half round under the chest with the legs swapped,
and the whole body facing away.  Checked against closed forms: the twist added and removed exactly, the
chest untouched, each limb segment pointing as the other side's, and turning round twice giving back the
truth's trunk and limb directions."""
import numpy as np
import pytest

from articula.sample_scenes.registered import posed_sequence

from articula.solver.geometry.rotations import matrix_to_quat, quat_to_matrix, rotvec_to_matrix
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Poses
from articula.solver.roles import role_bones
from articula.solver.tracking import checks
from articula.solver.tracking.joint_limits import signed_twist
from articula.solver.tracking.trunk_starts import (END_SEGMENTS, LIMB_SEGMENTS, _child_towards, turned_round_start,
                                                   untwisted_starts)

from .test_start_search import _model


@pytest.fixture(scope="module")
def subject():
    """(model, a range-of-motion pose) of a mixamo-rigged MakeHuman subject (another rig than the checks')."""
    _, _, gt = posed_sequence(rig="mixamo", shape="male", n_poses=2, motion="rom", skin="hybrid", seed=7,
                              amplitude=0.3)
    model, _ = _model(gt)
    return model, Poses(gt["pose_rotations"][1:2], gt["pose_translations"][1:2], gt["pose_scales"][1:2])


def _maps(model, pose):
    Rm, tm = forward_kinematics(model.skeleton, pose)
    return Rm[0] / np.cbrt(np.linalg.det(Rm[0]))[:, None, None], tm[0]


def _joints(model, pose):
    Rm, tm = forward_kinematics(model.skeleton, pose)
    return np.einsum("bij,bj->bi", Rm[0], model.skeleton.heads) + tm[0]


def _direction(model, W, b):
    d = W[b] @ (model.skeleton.tails[b] - model.skeleton.heads[b])
    return d / np.linalg.norm(d)


def _hips_turned(model, truth, trunk, deg):
    """``truth`` with the hips bone turned by ``deg`` about the spine's rest direction as the hips see it
    and the bone below it towards the chest turned back, so the chest stays and the legs come along."""
    sk = model.skeleton
    hips, chest, axis, _ = trunk
    turn = rotvec_to_matrix(np.radians(deg) * axis)
    out = truth.take(0)
    F = sk.frames[hips]
    out.rotations[0, hips] = matrix_to_quat(quat_to_matrix(out.rotations[0, hips]) @ F.T @ turn @ F)
    child = _child_towards(sk.parents, hips, chest)
    F = sk.frames[child]
    out.rotations[0, child] = matrix_to_quat(F.T @ turn.T @ F @ quat_to_matrix(out.rotations[0, child]))
    return out


@pytest.mark.parametrize("deg", [140.0, -160.0])
def test_hips_turned_back_under_the_chest(subject, deg):
    model, truth = subject
    trunk = checks.prepare(model).trunk
    hips, chest = trunk[0], trunk[1]
    wrong = _hips_turned(model, truth, trunk, deg)
    W, _ = _maps(model, wrong)
    T, _ = _maps(model, truth)
    true_twist = signed_twist(T[chest].T @ T[hips], trunk[2])
    assert signed_twist(W[chest].T @ W[hips], trunk[2]) == pytest.approx(true_twist + np.radians(deg), abs=1e-9)
    np.testing.assert_allclose(W[chest], T[chest], atol=1e-9)
    kept, swapped = untwisted_starts(model, wrong, trunk)
    for start in (kept, swapped):
        Ws, _ = _maps(model, start)
        assert signed_twist(Ws[chest].T @ Ws[hips], trunk[2]) == pytest.approx(0.0, abs=1e-9)
        np.testing.assert_allclose(Ws[chest], W[chest], atol=1e-9)              # the chest stays
    roles = role_bones(model.skeleton.names)
    Ws, _ = _maps(model, swapped)
    for seg in ("thigh", "shin", "foot"):                                       # each leg as the other was
        for side, other in (("L", "R"), ("R", "L")):
            np.testing.assert_allclose(_direction(model, Ws, roles[f"{seg}.{side}"]),
                                       _direction(model, W, roles[f"{seg}.{other}"]), atol=1e-9)


def test_a_fit_facing_away_is_turned_round(subject):
    """The true pose turned round (half a turn of every trunk bone about itself, limbs aimed at the other
    side's, hands and feet at rest): turned round again, the trunk is the truth's and the upper and lower
arms and legs point as the truth's."""
    model, truth = subject
    trunk = checks.prepare(model).trunk
    roles = role_bones(model.skeleton.names)
    away = turned_round_start(model, truth, trunk)
    W0, _ = _maps(model, truth)
    W1, _ = _maps(model, away)
    for b in (trunk[0], trunk[1]):
        np.testing.assert_allclose(_direction(model, W1, b), _direction(model, W0, b), atol=1e-9)
        d = _direction(model, W0, b)
        np.testing.assert_allclose(W1[b], rotvec_to_matrix(np.pi * d) @ W0[b], atol=1e-9)
    for seg in LIMB_SEGMENTS:
        for side, other in (("L", "R"), ("R", "L")):
            np.testing.assert_allclose(_direction(model, W1, roles[f"{seg}.{side}"]),
                                       _direction(model, W0, roles[f"{seg}.{other}"]), atol=1e-9)
    for end in (roles[f"{seg}.{side}"] for seg in END_SEGMENTS for side in "LR"):
        np.testing.assert_allclose(np.abs(away.rotations[0, end]), [1, 0, 0, 0], atol=1e-9)    # at rest
    back = turned_round_start(model, away, trunk)
    Wb, _ = _maps(model, back)
    for b in (roles[f"{seg}.{side}"] for seg in LIMB_SEGMENTS for side in "LR"):
        np.testing.assert_allclose(_direction(model, Wb, b), _direction(model, W0, b), atol=1e-9)
    np.testing.assert_allclose(Wb[trunk[1]], W0[trunk[1]], atol=1e-9)
    assert np.abs(_joints(model, back) - _joints(model, truth))[[trunk[0], trunk[1]]].max() < 1e-6
