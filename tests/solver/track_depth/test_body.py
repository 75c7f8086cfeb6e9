"""The tracking body (linear-blend subset, world-axes joint increments) and its normal equations against
finite differences and a dense Jacobian."""
import numpy as np
import pytest

from articula.solver.rig.pose_sampling import random_poses
from articula.solver.track_depth.body import TrackingBody, ancestor_table, linear_blend_weights, spread_subset
from articula.solver.track_depth.normal_equations import System, cross


@pytest.fixture(scope="module")
def body(model):
    return TrackingBody(model, count=400)


def test_weights_rows_sum_to_one_and_subset_is_spread(model, body):
    w = linear_blend_weights(model)
    assert np.allclose(w.sum(axis=1), 1.0) and (w >= -1e-7).all()
    assert np.allclose(body.weights.sum(axis=1), 1.0)
    a, b = spread_subset(model.rest_vertices, 400, seed=3), spread_subset(model.rest_vertices, 400, seed=3)
    assert np.array_equal(a, b) and len(a) == 400 and len(np.unique(a)) == 400
    # spread: the subset's points are farther apart than a random pick's (nearest-neighbour median)
    from scipy.spatial import cKDTree
    rnd = np.random.default_rng(0).choice(model.num_vertices, 400, replace=False)
    nn = lambda ids: np.median(cKDTree(model.rest_vertices[ids]).query(model.rest_vertices[ids], 2)[0][:, 1])
    assert nn(a) > 1.3 * nn(rnd)


def test_ancestor_table():
    t = ancestor_table(np.array([-1, 0, 1, 0, 3]))
    assert t[2].tolist() == [True, True, True, False, False] and t[4].tolist() == [True, False, False, True, True]


def test_rest_pose_reproduces_rest_points(model, body):
    from articula.solver.rig.model import Poses
    posed = body.pose(Poses.identity(1, model.skeleton.num_bones))
    assert np.allclose(posed.points, model.rest_vertices[body.ids], atol=1e-12)
    assert np.allclose(posed.joints, model.skeleton.heads, atol=1e-12)


@pytest.mark.parametrize("seed", [1, 2])
def test_jacobian_matches_finite_differences(model, body, seed):
    p = random_poses(1, model.skeleton.num_bones, seed=seed)
    posed = body.pose(p)
    J = body.jacobian(posed)
    delta = np.random.default_rng(seed).normal(size=body.num_params) * 1e-6
    moved = body.pose(body.apply(p, delta, posed)).points - posed.points
    assert np.abs(moved - J @ delta).max() < 1e-3 * np.abs(moved).max()


def test_joints_follow_forward_kinematics(model, body):
    from articula.solver.rig.kinematics import forward_kinematics
    p = random_poses(1, model.skeleton.num_bones, seed=4)
    Rm, tm = forward_kinematics(model.skeleton, p)
    assert np.allclose(body.pose(p).joints, np.einsum("bij,bj->bi", Rm[0], model.skeleton.heads) + tm[0])


def test_normal_equations_match_dense_jacobian(model, body):
    p = random_poses(1, model.skeleton.num_bones, seed=5)
    posed = body.pose(p)
    rng = np.random.default_rng(0)
    r, w = rng.normal(size=(len(body.ids), 3)), rng.random(len(body.ids))
    J = body.jacobian(posed).reshape(-1, body.num_params)
    W = np.repeat(w, 3)
    s = System(body.num_bones)
    s.add_points(body.lever_arms(posed), r, w)
    assert np.allclose(s.H, (J * W[:, None]).T @ J) and np.allclose(s.g, J.T @ (W * r.ravel()))
    h, e = rng.normal(size=(len(body.ids), 3)), rng.normal(size=len(body.ids))
    s2 = System(body.num_bones)
    s2.add_projected(body.lever_arms(posed), h, e, w)
    rows = np.einsum("mc,mcp->mp", h, body.jacobian(posed))
    assert np.allclose(s2.H, (rows * w[:, None]).T @ rows) and np.allclose(s2.g, rows.T @ (w * e))


def test_cross_matches_numpy():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(5, 4, 3)), rng.normal(size=(1, 4, 3))
    assert np.allclose(cross(a, b), np.cross(a, b))


def test_gauss_newton_step_recovers_a_small_pose_change(model, body):
    """Targets = the body in a nearby pose: a few solves bring the points onto them."""
    p0 = random_poses(1, model.skeleton.num_bones, seed=6)
    posed0 = body.pose(p0)
    truth = body.apply(p0, np.random.default_rng(2).normal(size=body.num_params) * 0.05, posed0)
    target = body.pose(truth).points
    p = p0
    for _ in range(6):
        posed = body.pose(p)
        s = System(body.num_bones)
        s.add_points(body.lever_arms(posed), posed.points - target, np.ones(len(target)))
        p = body.apply(p, s.solve(1e-9), posed)
    assert np.abs(body.pose(p).points - target).max() < 1e-5


def test_block_rows_match_dense_rows():
    rng = np.random.default_rng(2)
    B, bones = 6, np.array([1, 3, 4])
    cols = 3 + 3 * bones[:, None] + np.arange(3)
    D, e, w = rng.normal(size=(3, 3, 3)), rng.normal(size=(3, 3)), rng.random((3, 3))
    dense = np.zeros((3, 3, 3 + 3 * B))
    dense[np.arange(3)[:, None, None], np.arange(3)[None, :, None], cols[:, None, :]] = D
    a, b = System(B), System(B)
    a.add_blocks(cols, D, e, w)
    b.add_rows(dense.reshape(9, -1), e.ravel(), w.ravel())
    assert np.allclose(a.H, b.H) and np.allclose(a.g, b.g) and np.isclose(a.energy, b.energy)
