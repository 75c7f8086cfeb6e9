"""The blend body (linear-blend subset with lever arms, the exact body's parameters), its normal
equations, the box limits and the damped Gauss-Newton step, against finite differences, dense Jacobians
and closed forms."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from articula.sample_scenes import synthetic
from articula.solver.geometry.rotations import quat_to_rotvec
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Poses
from articula.solver.rig.pose_sampling import random_poses
from articula.solver.tracking.blend_body import BlendBody, ancestor_table, linear_blend_weights, spread_subset
from articula.solver.tracking.body import Body
from articula.solver.tracking.lm import gauss_newton_step, iterate, linearise_sum
from articula.solver.tracking.normal_equations import System, cross
from articula.solver.tracking.priors import JointBox, generic_limits, held_at


@pytest.fixture(scope="module")
def model():
    return synthetic.tube_body()


@pytest.fixture(scope="module")
def body(model):
    return BlendBody(model, count=400)


def _pose(model, seed, angle=0.5):
    p = random_poses(1, model.skeleton.num_bones, seed=seed, max_twist_deg=np.degrees(angle))
    p.translations[:] = np.random.default_rng(seed).normal(0, 0.1, 3)
    return p


def test_weights_rows_sum_to_one_and_subset_is_spread(model, body):
    w = linear_blend_weights(model)
    assert np.allclose(w.sum(axis=1), 1.0) and (w >= -1e-7).all()
    assert np.allclose(body.weights.sum(axis=1), 1.0)
    a, b = spread_subset(model.rest_vertices, 400, seed=3), spread_subset(model.rest_vertices, 400, seed=3)
    assert np.array_equal(a, b) and len(a) == 400 and len(np.unique(a)) == 400
    # spread: the subset's points are farther apart than a random pick's (nearest-neighbour median)
    rnd = np.random.default_rng(0).choice(model.num_vertices, 400, replace=False)
    nn = lambda ids: np.median(cKDTree(model.rest_vertices[ids]).query(model.rest_vertices[ids], 2)[0][:, 1])
    assert nn(a) > 1.3 * nn(rnd)


def test_ancestor_table():
    t = ancestor_table(np.array([-1, 0, 1, 0, 3]))
    assert t[2].tolist() == [True, True, True, False, False] and t[4].tolist() == [True, False, False, True, True]


def test_rest_pose_reproduces_rest_points(model, body):
    posed = body.pose(Poses.identity(1, model.skeleton.num_bones))
    assert np.allclose(posed.points, model.rest_vertices[body.ids], atol=1e-12)
    assert np.allclose(posed.joints, model.skeleton.heads, atol=1e-12)


def test_joints_follow_forward_kinematics(model, body):
    p = _pose(model, 4)
    Rm, tm = forward_kinematics(model.skeleton, p)
    assert np.allclose(body.pose(p).joints, np.einsum("bij,bj->bi", Rm[0], model.skeleton.heads) + tm[0])


def test_parameters_are_the_exact_bodys(model, body):
    """The same step moves a pose the same way on both bodies (right increments in bone-local axes)."""
    p = _pose(model, 7)
    step = np.random.default_rng(7).normal(0, 0.1, body.size)
    a, b = body.moved(p, step), Body(model).moved(p, step)
    assert body.size == Body(model).size and np.array_equal(body.columns, Body(model).columns)
    assert np.allclose(a.rotations, b.rotations) and np.allclose(a.translations, b.translations)


@pytest.mark.parametrize("seed", [1, 2])
def test_jacobian_matches_central_differences(model, body, seed):
    p = _pose(model, seed)
    posed = body.pose(p)
    J = body.jacobian(posed)
    rng = np.random.default_rng(seed)
    for k in rng.choice(body.size, 12, replace=False):
        e = np.zeros(body.size)
        e[k] = 1e-6
        fd = (body.pose(body.moved(p, e)).points - body.pose(body.moved(p, -e)).points) / 2e-6
        assert np.abs(fd - J[:, :, k]).max() < 1e-6 * max(1.0, np.abs(fd).max())


def test_motion_is_the_jacobian_times_the_step(model, body):
    p = _pose(model, 3)
    posed = body.pose(p)
    step = np.random.default_rng(3).normal(0, 1e-3, body.size)
    rows = np.arange(0, len(body.ids), 7)
    assert np.allclose(body.motion(posed, step, body.lever_arms(posed, rows)), body.jacobian(posed, rows) @ step)


def test_normal_equations_match_dense_jacobian(model, body):
    p = _pose(model, 5)
    posed = body.pose(p)
    rng = np.random.default_rng(0)
    r, w = rng.normal(size=(len(body.ids), 3)), rng.random(len(body.ids))
    J = body.jacobian(posed).reshape(-1, body.size)
    W = np.repeat(w, 3)
    s = System(body, posed)
    s.add_points(body.lever_arms(posed), r, w)
    lin = s.linear()
    assert np.allclose(lin.H, (J * W[:, None]).T @ J) and np.allclose(lin.g, J.T @ (W * r.ravel()))
    assert np.isclose(lin.energy, 0.5 * float((W * r.ravel() ** 2).sum()))
    h, e = rng.normal(size=(len(body.ids), 3)), rng.normal(size=len(body.ids))
    s2 = System(body, posed)
    s2.add_projected(body.lever_arms(posed), h, e, w)
    rows = np.einsum("mc,mcp->mp", h, body.jacobian(posed))
    lin2 = s2.linear()
    assert np.allclose(lin2.H, (rows * w[:, None]).T @ rows) and np.allclose(lin2.g, rows.T @ (w * e))


def test_cross_matches_numpy():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(5, 4, 3)), rng.normal(size=(1, 4, 3))
    assert np.allclose(cross(a, b), np.cross(a, b))


def test_gauss_newton_steps_recover_a_pose_change(model, body):
    """Targets = the body in a nearby pose: a few damped steps bring the points onto them (~0 error)."""
    p0 = _pose(model, 6)
    truth = body.moved(p0, np.random.default_rng(2).normal(size=body.size) * 0.05)
    target = body.pose(truth).points
    p = p0
    for _ in range(6):
        posed = body.pose(p)
        s = System(body, posed)
        s.add_points(body.lever_arms(posed), posed.points - target, np.ones(len(target)))
        p = body.moved(p, gauss_newton_step(s.linear(), 1e-9))
    assert np.abs(body.pose(p).points - target).max() < 1e-6


def test_gauss_newton_step_is_shortened_to_the_largest_turn():
    from articula.solver.tracking.terms import Linear
    H, g = np.eye(9), np.r_[0, 0, 0, 2.0, 0, 0, 0, 0.5, 0]
    step = gauss_newton_step(Linear(H, g, 0.0), 0.0, max_turn=0.5)
    assert np.allclose(step, -g * 0.25)


def _box(model):
    B = model.skeleton.num_bones
    lower, upper = np.full((B, 3), -0.2), np.full((B, 3), 0.3)
    lower[2], upper[2] = -np.inf, np.inf                                   # one free bone
    return JointBox(lower, upper, 10.0, centre_weight=0.5)


@pytest.mark.parametrize("which", ["blend", "exact"])
def test_box_gradient_matches_central_differences(model, body, which):
    """``g`` is the energy's derivative by the step on either body (the box's kink is avoided: every
    rotation is inside or well outside it)."""
    on = body if which == "blend" else Body(model)
    box = _box(model)
    p = _pose(model, 8, angle=0.9)
    posed = body.pose(p)
    lin = box.linearise(on, posed)
    assert np.isclose(lin.energy, box.energy(on, posed))
    for k in range(3, on.size, 5):
        e = np.zeros(on.size)
        e[k] = 1e-6
        up, down = body.pose(on.moved(p, e)), body.pose(on.moved(p, -e))
        fd = (box.energy(on, up) - box.energy(on, down)) / 2e-6
        assert abs(fd - lin.g[k]) < 1e-5 * max(1.0, abs(fd))


def test_box_limits_root_and_free_bones_and_holds(model, body):
    box = _box(model)
    assert 0 not in box.bones and 2 not in box.bones
    hold = held_at(model.skeleton.num_bones, [4, 5], np.full((2, 3), 0.1))
    assert hold.bones.tolist() == [4, 5]
    p = Poses.identity(1, model.skeleton.num_bones)
    # holding alone: the damped steps land on the held rotation
    for _ in range(4):
        p = body.moved(p, gauss_newton_step(linearise_sum([hold], body, body.pose(p)), 1e-9))
    assert np.allclose(quat_to_rotvec(p.rotations[0, [4, 5]]), 0.1, atol=1e-6)


def test_generic_limits_leave_the_root_free(model):
    limits = generic_limits(model.skeleton)
    assert 0 not in limits.bones and limits.centre_weight > 0


class _Registered:
    """A data term for :func:`iterate`: the subset's points to fixed targets (known correspondences)."""

    def __init__(self, target, scale=1.0, stop_after=None):
        self.target, self.prior_scale, self.stop_after, self.calls = target, scale, stop_after, 0

    def linearise(self, body, posed):
        self.calls += 1
        if self.stop_after is not None and self.calls > self.stop_after:
            return None
        s = System(body, posed)
        s.add_points(body.lever_arms(posed), posed.points - self.target, np.ones(len(self.target)))
        return s.linear()

    def converged(self, body, posed, moved, step) -> bool:
        return np.abs(moved.points - posed.points).max() < 1e-9


def test_iterate_reaches_the_truth_and_stops_as_told(model, body):
    p0 = _pose(model, 9)
    truth = body.moved(p0, np.random.default_rng(9).normal(size=body.size) * 0.1)
    target = body.pose(truth).points
    pose, posed, it = iterate(body, p0, _Registered(target), damping=1e-9, max_iterations=30)
    assert np.abs(posed.points - target).max() < 1e-7 and 2 <= it < 30
    assert np.allclose(posed.points, body.pose(pose).points)
    _, _, it = iterate(body, p0, _Registered(target, stop_after=2), damping=1e-9, max_iterations=30)
    assert it == 2                                                        # no linearisation: stop
    # a hold prior scaled far above the data keeps its bones where it holds them
    hold = held_at(model.skeleton.num_bones, [3], np.zeros((1, 3)))
    pose, _, _ = iterate(body, Poses.identity(1, model.skeleton.num_bones), _Registered(target, scale=1e6),
                         [hold], damping=1e-9, max_iterations=30)
    assert np.linalg.norm(quat_to_rotvec(pose.rotations[0, 3])) < 1e-3


def test_toward_pose_with_a_diagonal_weight_is_the_dense_sum(model, body):
    """A weight given as its diagonal (P,) is summed block by block to the dense ``Je^T W Je`` of the
    same diagonal matrix; :func:`toward_bones` weighs only the chosen bones' rotations."""
    from articula.solver.tracking.priors import TowardPose, toward_bones
    P = body.size
    w = np.random.default_rng(4).random(P)
    a, b = _pose(model, 10), _pose(model, 11)
    fast, dense = TowardPose(b, w), TowardPose(b, np.diag(w))
    lf, ld = fast.linearise(body, body.pose(a)), dense.linearise(body, body.pose(a))
    assert np.allclose(lf.H, ld.H) and np.allclose(lf.g, ld.g) and np.isclose(lf.energy, ld.energy)
    assert np.isclose(fast.energy(body, body.pose(a)), lf.energy)
    pull = toward_bones(b, P, [2, 5], 3.0)
    assert np.flatnonzero(pull.W).tolist() == [9, 10, 11, 18, 19, 20] and np.all(pull.W[[9, 18]] == 3.0)
