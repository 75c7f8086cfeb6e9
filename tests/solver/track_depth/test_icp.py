"""The ICP frame fit (depth-camera tracking dissertation ch. 5): correspondence rules, the projective edge
rows, and recovery of a known pose change from a rendered depth frame."""
import numpy as np
from articula.solver.track_depth import icp
from articula.solver.tracking.blend_body import BlendBody
from articula.solver.track_depth.options import DepthTrackOptions

from .conftest import front_camera, mild_poses, observation


def test_edge_residual_is_zero_on_the_matched_pixel(model):
    camera = front_camera(model)
    p = np.array([[0.1, -1.0, 1.2], [-0.2, -0.5, 0.4]])
    uv, _ = camera.project(p)
    h, e = icp.edge_rows(p, uv, camera)
    assert np.abs(e).max() < 1e-12
    h2, e2 = icp.edge_rows(p, uv + [3.0, 0.0], camera)      # 3 px off: metric error = 3 px x depth / fx
    depth = camera.to_camera(p)[:, 2]
    assert np.allclose(np.abs(e2[:2]), 3.0 * depth / camera.intr.fx)


def test_pairs_obey_distance_normal_and_bijectivity(model):
    camera = front_camera(model)
    pose = mild_poses(model, seed=0, angle=0.0)
    obs = observation(model, pose, camera)
    body = BlendBody(model, count=800)
    posed = body.pose(pose)
    vis = np.arange(len(body.ids))
    opts = DepthTrackOptions(max_distance=0.05)
    rows, targets = icp.surface_pairs(body, posed, vis, obs, opts)
    assert len(rows) > 100
    assert np.linalg.norm(posed.points[rows] - targets, axis=1).max() <= 0.05
    # flipped observed normals: no pair passes the 60 degree test
    obs.normals = -obs.normals
    assert len(icp.surface_pairs(body, posed, vis, obs, opts)[0]) < 0.03 * len(rows)


def test_relaxed_bijectivity_rejects_pairs_across_parts(model):
    """A model point whose nearest observed point is nearest to another part's point is dropped."""
    camera = front_camera(model)
    pose = mild_poses(model, seed=0, angle=0.0)
    obs = observation(model, pose, camera)
    body = BlendBody(model, count=800)
    posed = body.pose(pose)
    rows, _ = icp.surface_pairs(body, posed, np.arange(len(body.ids)), obs, DepthTrackOptions())
    # observed points 8 cm off: a target's nearest model point is now mostly another point; with every
    # point's main bone drawn at random those disagree, and the pairs go
    obs.points = obs.points + np.array([0.08, 0.0, 0.0])
    obs.__dict__.pop("_tree", None)
    shifted, _ = icp.surface_pairs(body, posed, np.arange(len(body.ids)), obs, DepthTrackOptions())
    body.main_bone = np.random.default_rng(0).integers(0, body.num_bones, len(body.main_bone))
    rows2, _ = icp.surface_pairs(body, posed, np.arange(len(body.ids)), obs, DepthTrackOptions())
    assert len(shifted) > 0.5 * len(rows) and len(rows2) < 0.6 * len(shifted)


def test_known_pose_change_is_recovered(model):
    """Up to 15 degrees per joint from the previous pose, rendered depth: the joints' error is more than
    halved and under 15 mm (from the true pose the linear-blend body stays about 6 mm off the rendered
    swing/twist skin); no joint limits (random poses leave the human box)."""
    camera = front_camera(model)
    start = mild_poses(model, seed=3, angle=0.3)
    body = BlendBody(model, count=1000)
    delta = np.zeros(body.size)
    rng = np.random.default_rng(4)
    delta[3:] = rng.uniform(-1, 1, 3 * body.num_bones) * np.radians(15) / np.sqrt(3)
    delta[3:6] = 0.0
    A = body.axes(body.pose(start))                          # the turns in world axes, as local increments
    delta[3:] = np.einsum("bji,bj->bi", A, delta[3:].reshape(-1, 3)).ravel()
    truth = body.moved(start, delta)
    obs = observation(model, truth, camera)
    fit = icp.fit_frame(body, obs, camera, start, DepthTrackOptions(max_iterations=30))
    err = np.linalg.norm(body.pose(fit.pose).joints - body.pose(truth).joints, axis=1)
    before = np.linalg.norm(body.pose(start).joints - body.pose(truth).joints, axis=1)
    big = np.flatnonzero(body.chain.sum(axis=0) > 20)        # joints carrying enough points to be seen
    assert np.median(err[big]) < 0.015 and np.median(err[big]) < 0.5 * np.median(before[big])
