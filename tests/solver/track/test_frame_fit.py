"""Per-frame fit of a fixed model to an unregistered capture (solver.track.frame_fit): the analytic
normal equations against central differences, exact recovery from a subsampled posed mesh, box limits,
and the MakeHuman subject's exact model on its own noisy 4-view scan."""
import numpy as np
import pytest

from articula.sample_scenes import registered, synthetic, unregistered
from articula.solver.geometry.rotations import quat_mul, quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.jacobians import apply_pose_increment, dense_jacobian
from articula.solver.rig.model import Model, Poses, Skeleton
from articula.solver.rig.skinning import AnchorGroups, hybrid_skin
from articula.solver.track import frame_fit as ff
from articula.solver.tracking.pose_prior import PosePrior
from articula.solver.geometry.normals import vertex_normals


def _one(poses, n=0):
    return Poses(poses.rotations[n:n + 1].copy(), poses.translations[n:n + 1].copy(), poses.scales[n:n + 1].copy())


def _perturbed(pose, rng, lo_deg, hi_deg, root_m):
    """``pose`` turned by lo..hi degrees about a random axis at every bone, the root moved by root_m."""
    B = pose.rotations.shape[1]
    axis = rng.normal(size=(B, 3))
    axis *= np.deg2rad(rng.uniform(lo_deg, hi_deg, B))[:, None] / np.linalg.norm(axis, axis=1, keepdims=True)
    move = rng.normal(size=3)
    return Poses(quat_mul(pose.rotations, rotvec_to_quat(axis[None])), pose.translations + root_m * move /
                 np.linalg.norm(move), pose.scales.copy())


@pytest.fixture(scope="module")
def tube():
    model = synthetic.tube_body()
    truth = synthetic.random_poses(1, model.skeleton.num_bones, seed=3, max_angle=0.4, translation=0.1,
                                   scale_range=(1.0, 1.0))
    return model, truth


def _pairs_at(model, pose, capture):
    return ff._refresh(model, AnchorGroups(model), pose, capture, ff.FrameFitOptions())


@pytest.mark.parametrize("plane", ["none", "model", "all"])
def test_data_normal_equations_match_central_differences(tube, plane):
    """H = JᵀSJ and g = JᵀS r of the barycentric model points (point-to-point, or point-to-plane along the
    target normal for the pairs of ``plane``), J by central differences of the residuals over the pose
    increments of rig.jacobians (translation, scale, every bone's rotation)."""
    model, truth = tube
    rng = np.random.default_rng(1)
    posed = hybrid_skin(model, truth)[0]
    capture = ff.Capture.from_mesh(posed + rng.normal(scale=0.01, size=posed.shape), model.faces)
    pose = _perturbed(truth, rng, 5, 10, 0.02)
    pose.scales[:] = 1.1
    pairs = _pairs_at(model, pose, capture)
    assert len(pairs.distances) > 1000 and (pairs.weights[:, 1:] > 0).any()      # surface points take part
    mask = ff.plane_mask(pairs, plane)
    scale = rng.uniform(0.5, 2.0, len(pairs.distances))
    B = model.skeleton.num_bones
    cols = ff.pose_columns(B, True)
    posed, J = dense_jacobian(model, pose, cols, 4 + 3 * B)
    H, g, E = ff.data_system(J[0], posed[0], pairs, scale, mask)

    def residual(delta):
        e = pairs.model_points(hybrid_skin(model, apply_pose_increment(pose, delta[None]))[0]) - pairs.targets
        n = pairs.target_normals
        return e if mask is None else np.where(mask[:, None], np.sum(n * e, axis=1, keepdims=True) * n, e)
    h = 1e-6
    Jfd = np.stack([(residual(h * e) - residual(-h * e)) / (2 * h) for e in np.eye(4 + 3 * B)], axis=-1)
    r = residual(np.zeros(4 + 3 * B))
    H_ref = np.einsum("c,cip,ciq->pq", scale, Jfd, Jfd)
    g_ref = np.einsum("c,cip,ci->p", scale, Jfd, r)
    assert np.isclose(E, np.einsum("c,ci,ci->", scale, r, r), rtol=1e-12)
    assert np.abs(H - H_ref).max() < 1e-6 * np.abs(H_ref).max()
    assert np.abs(g - g_ref).max() < 1e-6 * np.abs(g_ref).max()


def test_model_pairs_point_to_plane_distances(tube):
    """With to_plane="model" a model pair's distance is |n · (x_v − y)| along the capture normal, the
    capture pairs' stay 3-D; Q^data is the Charbonnier mean of those distances."""
    model, truth = tube
    posed = hybrid_skin(model, truth)[0]
    rng = np.random.default_rng(4)
    capture = ff.Capture.from_mesh(posed + rng.normal(scale=0.005, size=posed.shape), model.faces)
    point = ff._refresh(model, AnchorGroups(model), truth, capture, ff.FrameFitOptions(to_plane="none"))
    plane = _pairs_at(model, truth, capture)
    m = ~plane.from_capture
    along = np.abs(np.sum(plane.target_normals[m] * (posed[plane.vertex_ids[m, 0]] - plane.targets[m]), axis=1))
    assert np.allclose(plane.distances[m], along) and np.array_equal(plane.distances[~m], point.distances[~m])
    assert (plane.distances[m] <= point.distances[m] + 1e-15).all()
    assert np.isclose(plane.energy, np.mean(np.sqrt(plane.distances ** 2 + 1e-6)))


def test_update_gradient_with_prior_and_bounds_matches_its_energy(tube):
    """The update's gradient (data + prior, bounded bones in exp-map coordinates) is half the central
    difference of its energy along every free coordinate."""
    model, truth = tube
    rng = np.random.default_rng(2)
    sk = model.skeleton
    train = synthetic.random_poses(12, sk.num_bones, seed=5, max_angle=0.5)
    prior = PosePrior.from_poses(sk, train, k_max=2, margin=0.5)
    posed = hybrid_skin(model, truth)[0]
    capture = ff.Capture.from_mesh(posed, model.faces)
    pose = _perturbed(truth, rng, 5, 10, 0.02)
    options = ff.FrameFitOptions(w_pose=0.01)
    update = ff._Update(model, AnchorGroups(model), pose, _pairs_at(model, pose, capture), prior, options)
    assert update.bounded[1:].all() and not update.bounded[0]
    update.build(None)
    h = 1e-6
    fd = [(update.energy_at(update.moved(h * e)) - update.energy_at(update.moved(-h * e))) / (2 * h)
          for e in np.eye(len(update.g))]
    assert np.allclose(fd, 2 * update.g, rtol=1e-5, atol=1e-7 * np.abs(update.g).max())


def test_exact_capture_recovers_the_pose(tube):
    """A random 60 % of the posed vertices (with their normals) as a point cloud; the fit from the root
    moved by 1 cm returns the vertices to well under 1 mm RMS."""
    model, truth = tube
    rng = np.random.default_rng(0)
    posed = hybrid_skin(model, truth)[0]
    keep = rng.random(len(posed)) < 0.6
    capture = ff.Capture(posed[keep], vertex_normals(posed, model.faces)[keep])
    start = _perturbed(truth, rng, 0, 0, 0.01)
    out = ff.fit_frame(model, capture, start)
    rms = np.sqrt(np.mean(np.sum((hybrid_skin(model, out.pose)[0] - posed) ** 2, axis=1)))
    print(f"exact capture: RMS {rms * 1e3:.3f} mm after {out.iterations} updates")
    assert rms < 1e-3
    assert out.stats["median_mm"] < 0.1 and 0.2 < out.stats["removed_capture"] < 0.8
    stages = len(ff.FrameFitOptions().depth_stages) + 1
    assert len(out.log["Q"]) == out.iterations + stages and out.log["Q"].min() < 0.3 * out.log["Q"][0]


def test_a_dof_pushed_beyond_its_bound_ends_on_the_bound(tube):
    """The capture bends a joint past the prior's box: the fitted rotation vector sits on that bound
    (active set), every other DoF inside its interval."""
    model, truth = tube
    sk = model.skeleton
    prior = PosePrior.from_poses(sk, synthetic.random_poses(8, sk.num_bones, seed=4, max_angle=0.3), k_max=1,
                                 sparsify=False)
    r = quat_to_rotvec(truth.rotations[0])
    b = 7                                                       # upper_arm.L
    inside = np.clip(r, prior.lower, prior.upper)
    beyond = inside.copy()
    beyond[b, 0] = prior.upper[b, 0] + 0.3
    bent = Poses(rotvec_to_quat(beyond)[None], truth.translations, truth.scales)
    posed = hybrid_skin(model, bent)[0]
    capture = ff.Capture(posed, vertex_normals(posed, model.faces))
    start = Poses(rotvec_to_quat(inside)[None], truth.translations, truth.scales)
    out = ff.fit_frame(model, capture, start, prior, ff.FrameFitOptions(w_pose=1e-6))
    fitted = quat_to_rotvec(out.pose.rotations[0])
    assert abs(fitted[b, 0] - prior.upper[b, 0]) < 1e-9
    assert np.all(fitted >= prior.lower - 1e-9) and np.all(fitted <= prior.upper + 1e-9)


@pytest.fixture(scope="module")
def makehuman_walk():
    frames, faces, gt = registered.posed_sequence(n_poses=4, motion="walk", skin="hybrid", seed=0)
    sk = Skeleton(list(gt["bone_names"]), gt["parents"], gt["heads"], gt["tails"], gt["frames"])
    model = Model(gt["rest_vertices"], gt["faces"], sk, gt["anchor"], gt["twist_weights"], gt["swing_weights"])
    return model, Poses(gt["pose_rotations"], gt["pose_translations"], gt["pose_scales"]), frames


def test_exact_model_on_its_noisy_scan_from_the_previous_pose(makehuman_walk):
    """The subject's exact model on its own noisy 4-view scan (sample_scenes.unregistered) of walk frame 1,
    starting from frame 0's true pose: the error must fall well below the start's (7.6 mm of 21.3 mm with
    the default coarse-to-fine stages).  The issue's target is 3 mm mean vertex error; where the fit
    stands is in docs/track.md "Per-frame fit"."""
    model, poses, frames = makehuman_walk
    points, tris, _, _, cams = unregistered.scan_frame(frames[1], model.faces, np.random.default_rng([0, 1]))
    out = ff.fit_frame(model, ff.Capture.from_mesh(points, tris, cams), _one(poses, 0))
    start = np.linalg.norm(hybrid_skin(model, _one(poses, 0))[0] - frames[1], axis=1).mean()
    error = np.linalg.norm(hybrid_skin(model, out.pose)[0] - frames[1], axis=1).mean()
    print(f"MakeHuman walk frame 1: mean vertex error {error * 1e3:.2f} mm (start {start * 1e3:.2f} mm), "
          f"median scan-to-model {out.stats['median_mm']:.2f} mm, {out.iterations} updates")
    assert error < 0.5 * start and error < 0.010
    assert out.stats["median_mm"] < 5.0


def test_a_start_outside_the_box_is_moved_into_it_and_the_fit_proceeds(tube):
    """The capture and the start bend a joint past its bound (ordinary motion that few training poses did
    not cover); the start is clamped into the box first and the root, 2 cm off, is recovered.  Without
    the clamp every step pulls the joint back onto its bound whatever the step length, the line search
    finds no decrease and the fit ends where it started."""
    model, truth = tube
    sk = model.skeleton
    prior = PosePrior.from_poses(sk, synthetic.random_poses(8, sk.num_bones, seed=4, max_angle=0.3), k_max=1,
                                 sparsify=False)
    r = np.clip(quat_to_rotvec(truth.rotations[0]), prior.lower, prior.upper)
    r[7, 0] = prior.upper[7, 0] + 0.3
    bent = Poses(rotvec_to_quat(r)[None], truth.translations, truth.scales)
    posed = hybrid_skin(model, bent)[0]
    capture = ff.Capture(posed, vertex_normals(posed, model.faces))
    start = Poses(bent.rotations, truth.translations + [0.02, 0.0, 0.0], truth.scales)
    out = ff.fit_frame(model, capture, start, prior, ff.FrameFitOptions(w_pose=1e-6))
    fitted = quat_to_rotvec(out.pose.rotations[0])
    assert np.all(fitted >= prior.lower - 1e-9) and np.all(fitted <= prior.upper + 1e-9)
    assert np.linalg.norm(out.pose.translations - truth.translations) < 5e-3
