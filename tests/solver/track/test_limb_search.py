"""Limb placement on the first frame (solver.track.limb_search): the search order against brute force, and
arms put back where an exact capture has them on the arm body (the direction lattice and the tree helpers:
tests/solver/tracking/test_limbs.py)."""
import numpy as np

from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.track import limb_search as ls

from .arm_body import arm_body


def test_search_order_is_by_depth_then_index():
    parents = [-1, 0, 1, 2, 0, 4, 5, 0, 7]

    def ancestors(b):
        out = []
        while b >= 0:
            out.append(b)
            b = parents[b]
        return out

    order = ls.search_order(parents)
    depth = [len(ancestors(b)) - 1 for b in range(1, len(parents))]
    assert sorted(order) == list(range(1, len(parents)))
    assert [len(ancestors(b)) - 1 for b in order] == sorted(depth)


def test_arms_turned_away_are_put_back_on_an_exact_capture():
    """Both upper arms start 100 deg away from where the capture has them (chest placed): after the
    search every arm bone's direction is within the lattice spacing of the truth and the mean vertex
    error drops below a fifth; a start already right stays right (no turn beats it by the gain)."""
    model = arm_body()
    sk = model.skeleton
    r = np.zeros((sk.num_bones, 3))
    r[2] = [0.0, 0.4, 0.5]                       # upper_arm.L
    r[3] = [0.0, 0.0, 0.6]                       # forearm.L bent
    r[6] = [0.0, -0.3, -0.4]                     # upper_arm.R
    truth = Poses(rotvec_to_quat(r)[None], np.zeros((1, 3)), np.ones(1))
    points = hybrid_skin(model, truth)[0]
    wrong = r.copy()
    wrong[2] += [1.2, 0.0, -1.2]
    wrong[6] += [-1.2, 0.0, 1.2]
    start = Poses(rotvec_to_quat(wrong)[None], np.zeros((1, 3)), np.ones(1))
    before = np.linalg.norm(hybrid_skin(model, start)[0] - points, axis=1).mean()
    out = ls.place_limbs(model, start, points)
    after = np.linalg.norm(hybrid_skin(model, out)[0] - points, axis=1).mean()
    assert after < 0.2 * before
    Rt, tt = forward_kinematics(sk, truth)
    Ro, to = forward_kinematics(sk, out)
    for b in (2, 3, 6, 7):
        axis_t = Rt[0, b] @ (sk.tails[b] - sk.heads[b])
        axis_o = Ro[0, b] @ (sk.tails[b] - sk.heads[b])
        angle = np.degrees(np.arccos(axis_t @ axis_o / np.linalg.norm(axis_t) / np.linalg.norm(axis_o)))
        assert angle < 30.0, (sk.names[b], angle)
    np.testing.assert_array_equal(out.rotations[0, 0], start.rotations[0, 0])
    kept = ls.place_limbs(model, truth, points)
    np.testing.assert_allclose(quat_to_rotvec(kept.rotations), quat_to_rotvec(truth.rotations), atol=1e-9)
