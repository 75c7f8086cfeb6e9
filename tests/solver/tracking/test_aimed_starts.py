"""Limbs aimed at unexplained capture (solver.tracking.aimed_starts) against closed forms and ground truth:
the world turn between two directions, and on a MakeHuman subject a forearm folded away from its true place
brought back by aiming it at the centre of the capture it left (the true forearm's vertices)."""
import numpy as np
import pytest

from articula.sample_scenes.registered import posed_sequence
from articula.solver.geometry.rotations import rotvec_to_matrix
from articula.solver.rig.jacobians import apply_pose_increment
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.roles import role_bones
from articula.solver.tracking.aimed_starts import SEGMENTS, aimed_starts, limb_reach, turn_between

from .test_start_search import _model


@pytest.fixture(scope="module")
def subject():
    _, _, gt = posed_sequence(rig="game_engine", shape="female", n_poses=2, motion="rom", skin="hybrid", seed=4,
                              amplitude=0.3)
    model, _ = _model(gt)
    from articula.solver.rig.model import Poses
    truth = Poses(gt["pose_rotations"][1:2], gt["pose_translations"][1:2], gt["pose_scales"][1:2])
    return model, truth


@pytest.mark.parametrize("d, u", [((1, 0, 0), (0, 1, 0)), ((0, 0, 1), (0.3, -0.2, 0.9)), ((1, 2, 3), (1, 2, 3)),
                                  ((0, 0, 1), (0, 0, -1)), ((1, -1, 0.5), (-1, 1, -0.5))])
def test_the_turn_between_two_directions_takes_one_onto_the_other(d, u):
    d, u = np.array(d, float), np.array(u, float)
    omega = turn_between(d, u)
    np.testing.assert_allclose(rotvec_to_matrix(omega) @ (d / np.linalg.norm(d)), u / np.linalg.norm(u), atol=1e-12)
    cos = np.clip(d @ u / np.linalg.norm(d) / np.linalg.norm(u), -1, 1)
    assert np.linalg.norm(omega) == pytest.approx(np.arccos(cos), abs=1e-9)   # the shortest turn


def test_a_limbs_reach_is_its_farthest_vertex(subject):
    model, _ = subject
    reach = limb_reach(model)
    b = role_bones(model.skeleton.names)["upper_arm.R"]
    assert 0.45 < reach[b] < 0.9                              # shoulder to fingertips of an adult, metres
    assert reach[role_bones(model.skeleton.names)["forearm.R"]] < reach[b]


def test_a_folded_forearm_aimed_at_the_capture_it_left_comes_back(subject):
    """The true forearm folded 100 deg about its elbow: the aimed start that turns the forearm points its
    axis at the centre of the true forearm-and-hand vertices, and brings those vertices from far off to a
    few centimetres (the turn about the axis is left to the fit)."""
    model, truth = subject
    sk, roles = model.skeleton, role_bones(model.skeleton.names)
    fa = roles["forearm.R"]
    fold = np.zeros((1, 4 + 3 * sk.num_bones))
    fold[0, 4 + 3 * fa:7 + 3 * fa] = np.radians(100.0) * np.array([1.0, 0.0, 0.0])
    folded = apply_pose_increment(truth, fold)
    below = [b for b in range(sk.num_bones) if b == fa or fa in _ancestors(sk.parents, b)]
    part = np.isin(model.anchor, below)
    target = hybrid_skin(model, truth)[0][part]
    centre = target.mean(axis=0)
    far = np.linalg.norm(hybrid_skin(model, folded)[0][part] - target, axis=1).mean()
    starts = aimed_starts(model, folded, [centre])
    assert 1 <= len(starts) <= len(SEGMENTS)
    errors = [np.linalg.norm(hybrid_skin(model, s)[0][part] - target, axis=1).mean() for s in starts]
    assert far > 0.15 and min(errors) < 0.05, (far, errors)
    Rm, tm = forward_kinematics(sk, starts[int(np.argmin(errors))])
    joint = Rm[0, fa] @ sk.heads[fa] + tm[0, fa]
    axis = Rm[0, fa] @ (sk.tails[fa] - sk.heads[fa])
    to = centre - joint
    assert axis @ to / np.linalg.norm(axis) / np.linalg.norm(to) > 1 - 1e-9     # pointing at the centre


def _ancestors(parents, b):
    out = []
    while parents[b] >= 0:
        b = parents[b]
        out.append(b)
    return out
