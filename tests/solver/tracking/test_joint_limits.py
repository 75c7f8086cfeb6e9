"""Hinge axes of knees and elbows (:func:`solver.tracking.joint_limits.hinges_of`) and their angles
(:func:`~solver.tracking.joint_limits.hinge_angles`) in closed form, on hand-made three-joint arms."""
import numpy as np
import pytest

from articula.solver.geometry.rotations import rotvec_to_matrix
from articula.solver.rig.model import Skeleton
from articula.solver.tracking.joint_limits import HINGE_AXIS_DEG, hinge_angles, hinges_of

FORWARD = np.array([0.0, -1.0, 0.0])          # where the feet point


def _arm(upper_dir, bend_deg, towards):
    """A left arm: shoulder at the origin, a 0.3 m upper arm along ``upper_dir``, a 0.25 m forearm bent
    ``bend_deg`` from it towards the direction ``towards``, a hand bone after it."""
    t = np.asarray(upper_dir, float) / np.linalg.norm(upper_dir)
    normal = np.cross(t, towards)
    u = rotvec_to_matrix(np.radians(bend_deg) * normal / np.linalg.norm(normal)) @ t
    heads = np.array([[0, 0, 0], 0.3 * t, 0.3 * t + 0.25 * u], float)
    tails = heads + np.array([0.3 * t, 0.25 * u, 0.1 * u])
    names = ["upper_arm.L", "forearm.L", "hand.L"]
    sk = Skeleton(names, np.array([-1, 0, 1]), heads, tails, np.tile(np.eye(3), (3, 1, 1)))
    return sk, {n: k for k, n in enumerate(names)}


def _bent(sk, hinge, degrees):
    """Part maps ``(Rm (B, 3, 3), tm (B, 3))`` with the forearm and hand turned ``degrees`` about the
    hinge's axis at the elbow."""
    R = rotvec_to_matrix(np.radians(degrees) * hinge.axis)
    Rm, tm = np.tile(np.eye(3), (3, 1, 1)), np.zeros((3, 3))
    elbow = sk.heads[1]
    Rm[1:], tm[1:] = R, elbow - R @ elbow
    return Rm, tm


@pytest.mark.parametrize("bend", [12.0, 18.0, 40.0])
def test_an_elbow_bent_at_rest_flexes_in_its_own_plane_wherever_the_arm_points(bend):
    """An arm raised forwards and up, bent in a plane the feet's forward says nothing about: its axis is
    the rest plane's normal, so bending it on reads more flexion and straightening it past straight reads
    backwards; the sideways bend is checked only from 25 deg of rest bend."""
    sk, roles = _arm([0.3, -0.6, 0.7], bend, [0.8, 0.0, 0.6])
    [elbow], notes = hinges_of(sk, roles, {"L": FORWARD, "R": FORWARD})
    t = sk.heads[1] - sk.heads[0]
    u = sk.heads[2] - sk.heads[1]
    normal = np.cross(t, u) / np.linalg.norm(np.cross(t, u))
    np.testing.assert_allclose(elbow.axis, normal, atol=1e-9)
    for turn in (0.0, 20.0, -bend, -bend - 15.0):
        flexion, side = hinge_angles(elbow, *_bent(sk, elbow, turn))
        assert flexion == pytest.approx(bend + turn, abs=1e-6)
        assert side == pytest.approx(0.0, abs=1e-6)
    assert elbow.sideways == (bend >= 25.0)
    assert any("sideways bend is not checked" in n for n in notes) == (bend < 25.0)


def test_a_straight_elbow_flexes_towards_where_the_feet_point():
    """Below ``HINGE_AXIS_DEG`` of rest bend the plane is too uncertain: an arm held out sideways flexes its
    forearm forwards."""
    sk, roles = _arm([1.0, 0.0, 0.0], 0.5 * HINGE_AXIS_DEG, [0.0, 1.0, 0.0])
    [elbow], notes = hinges_of(sk, roles, {"L": FORWARD, "R": FORWARD})
    Rm, tm = _bent(sk, elbow, 30.0)
    hand = Rm[2] @ sk.heads[2] + tm[2]
    assert (hand - sk.heads[1]) @ FORWARD > 0.1                # the forearm swung forwards
    assert not elbow.sideways and any(n.startswith("left elbow: straight at rest") for n in notes)
