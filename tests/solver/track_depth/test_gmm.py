"""The GMM/EM depth tracker (solver.track_depth.gmm, depth-camera tracking dissertation ch. 6): the E-step
against a direct mixture evaluation, the CPD reduction and sigma^2 update, the prediction rows, and
fits of the built-in template body to synthetic complete clouds and a single-view render."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from articula.sample_scenes.depth_render import render_depth
from articula.solver.depth.camera import look_at, preset
from articula.solver.geometry.rotations import quat_conj, quat_mul, quat_to_rotvec, rotvec_to_quat
from articula.solver.geometry.surface_distance import distance_to_surface
from articula.solver.rig.model import Poses
from articula.solver.geometry.normals import vertex_normals
from articula.solver.track_depth import gmm
from articula.solver.tracking.blend_body import BlendBody
from articula.solver.tracking.priors import generic_limits
from articula.solver.track_depth.observation import Observation, ViewCamera
from articula.solver.track_depth.options import DepthTrackOptions
from articula.solver.track_depth.template import load_template
from articula.solver.track_depth.trackers import frame_fitter

ARM, FOREARM, HAND = 10, 11, 12          # Arm.L, ForeArm.L, Hand.L of the template's cmu_mb skeleton


@pytest.fixture(scope="module")
def model():
    return load_template().base


@pytest.fixture(scope="module")
def body(model):
    return BlendBody(model, count=1000)


@pytest.fixture(scope="module")
def full(model):
    return BlendBody(model, ids=np.arange(model.num_vertices))


def posed(model, elbow_deg=0.0, forearm_axis=(1.0, 0.0, 0.0)):
    """Arm.L lowered, ForeArm.L bent by 17 deg plus ``elbow_deg`` about its local ``forearm_axis``."""
    rot = np.tile([1.0, 0.0, 0.0, 0.0], (model.skeleton.num_bones, 1))
    rot[ARM] = rotvec_to_quat(np.array([0.0, 0.0, -1.0]))
    axis = np.asarray(forearm_axis) / np.linalg.norm(forearm_axis)
    rot[FOREARM] = rotvec_to_quat(np.array([0.3, 0.0, 0.0]) + np.radians(elbow_deg) * axis)
    return Poses(rot[None], np.zeros((1, 3)), np.ones(1))


def surface_points(model, full, pose, count, seed=0):
    """``count`` points spread uniformly by area over the posed mesh."""
    rng = np.random.default_rng(seed)
    v, f = model.rest_vertices, model.faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    tri = rng.choice(len(f), count, p=area / area.sum())
    b = rng.random((count, 2))
    b[b.sum(axis=1) > 1] = 1 - b[b.sum(axis=1) > 1]
    p = full.pose(pose).points[f[tri]]
    return p[:, 0] + b[:, :1] * (p[:, 1] - p[:, 0]) + b[:, 1:] * (p[:, 2] - p[:, 0])


def observation(points):
    n = len(points)
    return Observation(points, np.zeros((n, 3)), np.zeros((n, 2)), np.zeros(n, bool), np.zeros((0, 3)),
                       np.zeros((0, 2)), np.zeros((0, 2)), np.ones((2, 2), bool), np.ones((2, 2)), n)


def bone_direction(model, body, pose, bone):
    sk = model.skeleton
    d = sk.tails[bone] - sk.heads[bone]
    d = body.pose(pose).world[bone] @ d
    return d / np.linalg.norm(d)


def angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0)))


def test_posterior_is_the_mixture_posterior():
    rng = np.random.default_rng(0)
    v = rng.random((40, 3)) * 0.3
    x = np.concatenate([v[rng.integers(0, 40, 50)] + 0.01 * rng.standard_normal((50, 3)),
                        rng.random((10, 3)) * 0.6 - 0.15])
    sigma2, u = 0.02 ** 2, 0.01
    N, M = len(x), len(v)
    idx, p = gmm.posterior(x, v, sigma2, u)
    assert idx.shape == p.shape == (N, M)
    dense = np.zeros((N, M))
    dense[np.arange(N)[:, None], idx] = p
    # Eq. 6.1-6.2: p(x) = (1 - u) sum_m N(x; v_m, sigma^2 I) / M + u / N, and the posterior of each component
    d2 = ((x[:, None] - v[None]) ** 2).sum(axis=2)
    comp = (1 - u) / M * np.exp(-d2 / (2 * sigma2)) / (2 * np.pi * sigma2) ** 1.5
    direct = comp / (comp.sum(axis=1, keepdims=True) + u / N)
    np.testing.assert_allclose(dense, direct, rtol=1e-10, atol=1e-14)
    assert np.all(dense.sum(axis=1) <= 1 + 1e-12) and dense.sum(axis=1).min() < 0.5   # outliers exist
    idx8, p8 = gmm.posterior(x, v, sigma2, u, neighbours=8)       # truncated E-step
    trunc = np.zeros((N, M))
    trunc[np.arange(N)[:, None], idx8] = p8
    np.testing.assert_allclose(trunc, direct, atol=1e-5)         # the dropped terms are below exp(-14)


def test_reduction_and_sigma_update_are_the_dense_sums():
    rng = np.random.default_rng(1)
    v, x = rng.random((30, 3)) * 0.2, rng.random((80, 3)) * 0.2
    idx, p = gmm.posterior(x, v, 0.03 ** 2, 0.01)
    P1, PX = gmm.reduce(x, idx, p, len(v))
    np.testing.assert_allclose(P1, p.sum(axis=0))
    np.testing.assert_allclose(PX, p.T @ x)
    d2 = ((x[:, None] - v[None]) ** 2).sum(axis=2)
    assert gmm.sigma2_update(x, v, idx, p) == pytest.approx((p * d2).sum() / (3 * p.sum()))   # Eq. 6.11


def test_prediction_rows_are_the_linearised_rotation_gap(model, body):
    """E_p's gradient is the central difference of ``sum |log(q_pred^-1 q)|^2`` (non-root joints) and its
    normal matrix adds ``weight J^T J``; the root's position and turn are free."""
    rng = np.random.default_rng(2)
    B = model.skeleton.num_bones
    start = Poses(rotvec_to_quat(0.3 * rng.standard_normal((B, 3)))[None], np.zeros((1, 3)), np.ones(1))
    pred = Poses(quat_mul(rotvec_to_quat(0.2 * rng.standard_normal((B, 3))), start.rotations[0])[None],
                 np.zeros((1, 3)), np.ones(1))
    lin = gmm.prediction_term(body, pred, 1.0).linearise(body, body.pose(start))

    def energy(step):
        q = body.moved(start, step).rotations[0, 1:]
        return float((quat_to_rotvec(quat_mul(quat_conj(pred.rotations[0, 1:]), q)) ** 2).sum())

    assert 2 * lin.energy == pytest.approx(energy(np.zeros(3 + 3 * B)))
    h = 1e-6
    grad = [(energy(h * e) - energy(-h * e)) / (2 * h) for e in np.eye(3 + 3 * B)]
    np.testing.assert_allclose(grad, 2 * lin.g, atol=1e-6)
    assert not lin.g[:6].any()                                    # neither the root's position nor its turn


def complete_fit(model, body, full, true, start, extra=None, **kw):
    points = surface_points(model, full, true, 6000)
    if extra is not None:
        points = np.concatenate([points, extra])
    opts = DepthTrackOptions(tracker="gmm", gmm_points=10 ** 5, gmm_lambda_p=0.0, **kw)
    limits = [generic_limits(model.skeleton)]
    return gmm.fit_frame(body, observation(points), None, start, opts, limits, iterations=15)


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)])
def test_complete_cloud_recovers_a_30_degree_elbow_change(model, body, full, axis):
    true, start = posed(model, 30.0, axis), posed(model)
    fit = complete_fit(model, body, full, true, start)
    assert fit.iterations <= 15
    direction = {p: {b: bone_direction(model, body, pose, b) for b in (ARM, FOREARM)}
                 for p, pose in (("fit", fit.pose), ("true", true), ("start", start))}
    assert angle_deg(direction["start"][FOREARM], direction["true"][FOREARM]) > 25
    for bone in (ARM, FOREARM):            # world directions: the 1000-point model leaves about 2 deg
        assert angle_deg(direction["fit"][bone], direction["true"][bone]) < 3.0
    flex = {p: angle_deg(d[ARM], d[FOREARM]) for p, d in direction.items()}
    assert abs(flex["fit"] - flex["true"]) < 1.0
    wrist = np.linalg.norm(body.pose(fit.pose).joints[HAND] - body.pose(true).joints[HAND])
    assert wrist < 0.01


def test_far_outliers_barely_change_the_pose(model, body, full):
    true, start = posed(model, 15.0), posed(model)
    clean = complete_fit(model, body, full, true, start)
    rng = np.random.default_rng(3)
    box = rng.random((20000, 3)) * [2.0, 2.0, 2.2] - [1.0, 1.0, 0.1]
    far = box[cKDTree(full.pose(true).points).query(box)[0] > 0.15][:1200]   # 20% more points, >= 15 cm away
    noisy = complete_fit(model, body, full, true, start, extra=far)
    shift = np.linalg.norm(body.pose(noisy.pose).joints - body.pose(clean.pose).joints, axis=1)
    assert shift.max() < 0.003
    assert noisy.pairs < 6000 + 0.05 * len(far)             # the outliers carry almost no posterior mass


def render(model, full, pose, camera):
    """Grid-sampled points (tracking frame) of the posed mesh seen by ``camera``."""
    verts = full.pose(pose).points
    depth, _ = render_depth((verts - camera.t) @ camera.R, model.faces, camera.intr)
    rows, cols = np.nonzero(depth[::2, ::2] > 0)
    rows, cols = 2 * rows, 2 * cols
    z = depth[rows, cols]
    intr = camera.intr
    c = np.stack([(cols - intr.cx) * z / intr.fx, (rows - intr.cy) * z / intr.fy, z], axis=1)
    return c @ camera.R.T + camera.t


def signed_distances(model, full, pose, points):
    """Distances of ``points`` to the posed mesh, negative inside (sign from the nearest vertex normal)."""
    verts = full.pose(pose).points
    d = distance_to_surface(points, verts, model.faces)
    _, near = cKDTree(verts).query(points)
    side = ((points - verts[near]) * vertex_normals(verts, model.faces)[near]).sum(axis=1)
    return np.where(side < 0, -d, d)


def test_two_step_scheme_puts_the_data_on_the_visible_surface(model, body, full):
    camera = ViewCamera(preset("kinect_v1", (320, 240)), look_at((0.3, -2.6, 1.1), (0.0, 0.0, 0.95)))
    true = posed(model, 20.0)
    points = render(model, full, true, camera)
    start = posed(model)
    start = Poses(start.rotations, start.translations + [0.02, 0.04, -0.02], start.scales)
    opts = DepthTrackOptions(tracker="gmm", gmm_points=len(points), gmm_lambda_p=0.0, gmm_iterations=15)
    fit = frame_fitter(opts)(body, observation(points), camera, start, opts, [generic_limits(model.skeleton)])
    sd = signed_distances(model, full, fit.pose, points)
    assert abs(sd.mean()) < 0.002 and np.median(np.abs(sd)) < 0.004
    one = gmm.em(body, points, camera, gmm.EMState(start, opts.gmm_sigma ** 2), opts,
                 [generic_limits(model.skeleton)], None, 1, 15)              # step one alone: every point in view
    sinks = signed_distances(model, full, one.pose, points).mean()
    assert sinks < -0.0008 and abs(sd.mean()) < 0.6 * abs(sinks)     # the back surface pulls the data inside
    joints = np.linalg.norm(body.pose(fit.pose).joints - body.pose(true).joints, axis=1)
    assert joints.mean() < 0.02


def test_prediction_holds_an_unobserved_limb(model, body, full):
    true, start = posed(model), posed(model)
    predicted = posed(model, 20.0)
    points = surface_points(model, full, true, 6000)
    _, near = cKDTree(full.pose(true).points).query(points)
    points = points[~np.isin(full.main_bone[near], [FOREARM, HAND])]         # the forearm is not seen
    opts = DepthTrackOptions(tracker="gmm", gmm_points=10 ** 5, gmm_lambda_p=500.0)  # Table 6.2
    obs = observation(points)
    held = gmm.fit_frame(body, obs, None, start, opts, iterations=15, predicted=predicted)
    free = gmm.fit_frame(body, obs, None, start, opts, iterations=15)

    def gap(p, q):
        return np.degrees(np.linalg.norm(quat_to_rotvec(quat_mul(p.rotations[0, FOREARM],
                                                                 quat_conj(q.rotations[0, FOREARM])))))

    assert gap(held.pose, predicted) < 5.0                    # the hand still explains some hip points
    assert gap(free.pose, start) < 5.0 and gap(free.pose, predicted) > 15.0
