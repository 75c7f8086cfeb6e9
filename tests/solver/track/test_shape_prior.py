"""The shape prior of model adaptation (solver.track.shape_prior): its targets against the umbrella
Laplacians of the training meshes computed by hand (T6), its gradient and Gauss-Newton blocks in the rest
vertices and joint centres against central differences (T14), the pose spreading and the lift."""
import numpy as np
import pytest
import scipy.sparse as sp

from articula.sample_scenes import synthetic
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import AnchorGroups
from articula.solver.track.adapt import adapted_model
from articula.solver.track.shape_prior import ShapePrior, lift, spread_poses


@pytest.fixture(scope="module")
def tube():
    model = synthetic.tube_body(rings=6, segments=6)
    train = synthetic.random_poses(12, model.skeleton.num_bones, seed=1, max_angle=0.6, translation=0.1,
                                   scale_range=(1.0, 1.0))
    return model, train


def _umbrella(meshes, faces):
    """v − mean of its one-ring, by plain loops over the faces (reference)."""
    V = meshes.shape[1]
    ring = [set() for _ in range(V)]
    for f in faces:
        for i in range(3):
            ring[f[i]].update((f[(i + 1) % 3], f[(i + 2) % 3]))
    return np.stack([[m[v] - m[sorted(ring[v])].mean(axis=0) for v in range(V)] for m in meshes])


def test_unadapted_model_has_zero_shape_prior_and_the_training_laplacians(tube):
    """T6: the targets are the umbrella Laplacians of the training meshes whenever Chapter 3 fitted them
    exactly (the training mesh is then the model posed in its pose), so Q^shape of the unadapted model is
    0; moving one rest vertex or one joint makes it positive."""
    model, train = tube
    prior = ShapePrior.from_model(model, train, count=5)
    assert prior.num_poses == 5
    from articula.solver.rig.skinning import hybrid_skin
    meshes = hybrid_skin(model, prior.poses)
    assert np.abs(prior.targets - _umbrella(meshes, model.faces)).max() < 1e-12
    assert prior.value(model) == 0.0
    x = model.rest_vertices.copy()
    x[100] += [0.002, 0.0, 0.0]
    assert prior.value(adapted_model(model, x, model.skeleton.heads)) > 1e-9
    heads = model.skeleton.heads.copy()
    heads[7] += [0.0, 0.01, 0.0]
    assert prior.value(adapted_model(model, model.rest_vertices, heads)) > 1e-9


def test_without_training_poses_the_prior_uses_the_rest_pose(tube):
    model, _ = tube
    prior = ShapePrior.from_model(model, None)
    assert prior.num_poses == 1 and np.allclose(prior.poses.rotations[0, :, 0], 1.0)
    L = prior.L.toarray()
    assert np.allclose(prior.targets[0], L @ model.rest_vertices)


def test_spread_poses_start_near_rest_then_take_the_farthest():
    rng = np.random.default_rng(0)
    r = rng.normal(scale=0.5, size=(9, 4, 3))
    r[4] *= 0.01                                                       # nearest the rest pose
    from articula.solver.geometry.rotations import rotvec_to_quat
    poses = Poses(rotvec_to_quat(r), np.zeros((9, 3)), np.ones(9))
    chosen = spread_poses(poses, 3)
    feats = r[:, 1:].reshape(9, -1)
    first = 4
    second = int(np.argmax(np.linalg.norm(feats - feats[first], axis=1)))
    d = np.minimum(np.linalg.norm(feats - feats[first], axis=1), np.linalg.norm(feats - feats[second], axis=1))
    assert sorted(chosen.tolist()) == sorted([first, second, int(np.argmax(d))])
    assert spread_poses(poses, 20).tolist() == list(range(9))


def test_shape_prior_gradient_and_gauss_newton_blocks_match_central_differences(tube):
    """T14: g and H of Q^shape = (1/MV) Σ ‖L T_m(x, h) − target_m‖² in the rest vertices (a sample of
    coordinates) and in the joint centres of bones 1..B−1, against central differences of the residuals."""
    model, train = tube
    rng = np.random.default_rng(2)
    prior = ShapePrior.from_model(model, train, count=3)
    B, V = model.skeleton.num_bones, model.num_vertices
    x = model.rest_vertices + rng.normal(scale=0.003, size=(V, 3))
    heads = model.skeleton.heads.copy()
    heads[1:] += rng.normal(scale=0.01, size=(B - 1, 3))
    m = adapted_model(model, x, heads)
    H_xx, H_xh, H_hh, g_x, g_h, value = prior.system(m, AnchorGroups(m), 3 * (B - 1))
    assert np.isclose(value, prior.value(m), rtol=1e-12)
    scale = 1.0 / np.sqrt(prior.num_poses * V)

    def residual(dx, dh):
        mm = adapted_model(model, x + dx.reshape(V, 3), np.vstack([heads[:1], heads[1:] + dh.reshape(-1, 3)]))
        return prior.residuals(mm).ravel() * scale
    cols = rng.choice(3 * V, 25, replace=False)
    h = 1e-6
    Jx = np.stack([(residual(h * e, np.zeros(3 * (B - 1))) - residual(-h * e, np.zeros(3 * (B - 1)))) / (2 * h)
                   for e in np.eye(3 * V)[cols]], axis=1)
    Jh = np.stack([(residual(np.zeros(3 * V), h * e) - residual(np.zeros(3 * V), -h * e)) / (2 * h)
                   for e in np.eye(3 * (B - 1))], axis=1)
    r = residual(np.zeros(3 * V), np.zeros(3 * (B - 1)))
    for got, want in ((g_x[cols], Jx.T @ r), (g_h, Jh.T @ r), (H_hh, Jh.T @ Jh), (H_xh[cols], Jx.T @ Jh),
                      (H_xx[cols][:, cols].toarray(), Jx.T @ Jx)):
        assert np.abs(got - want).max() < 1e-6 * np.abs(want).max()


def test_lift_equals_the_dense_chain_rule():
    """lift: Aᵀ H A, Aᵀ H J, Jᵀ H J, Aᵀ b, Jᵀ b, with and without a ``used`` subset."""
    rng = np.random.default_rng(3)
    V, k = 7, 4
    M = rng.normal(size=(3 * V, 3 * V))
    used = np.array([1, 2, 5])
    rows = (3 * used[:, None] + np.arange(3)).ravel()
    H = np.zeros((3 * V, 3 * V))
    H[np.ix_(rows, rows)] = (M @ M.T)[np.ix_(rows, rows)]
    b = np.zeros(3 * V)
    b[rows] = rng.normal(size=len(rows))
    A, J = rng.normal(size=(V, 3, 3)), rng.normal(size=(V, 3, k))
    Ad = np.zeros((3 * V, 3 * V))
    for v in range(V):
        Ad[3 * v:3 * v + 3, 3 * v:3 * v + 3] = A[v]
    Jd = J.reshape(3 * V, k)
    want = (Ad.T @ H @ Ad, Ad.T @ H @ Jd, Jd.T @ H @ Jd, Ad.T @ b, Jd.T @ b)
    for u in (None, used):
        got = lift(sp.csr_matrix(H), b, A, J, u)
        assert np.allclose(got[0].toarray(), want[0]) and all(np.allclose(g, w) for g, w in zip(got[1:], want[1:]))
