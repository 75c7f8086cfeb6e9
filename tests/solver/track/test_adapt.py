"""Model adaptation (solver.track.adapt): the objective's gradient and the data term's Gauss-Newton blocks
against central differences (T14), the Schur solve against a dense solve, the gauge, the symmetry
constraint (T15), recovery of a planted subject from exact and from noisy scans (T20), bad input and
cancelling."""
import dataclasses

import numpy as np
import pytest

from articula.sample_scenes import synthetic, unregistered
from articula.sample_scenes.depth_noise import NOISELESS, NoiseParams
from articula.solver.errors import ArticulaInputError, Cancelled
from articula.solver.geometry.rotations import quat_mul, rotvec_to_quat
from articula.solver.rig.jacobians import dense_jacobian
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import AnchorGroups, affine_form, hybrid_skin
from articula.solver.track import adapt as ad
from articula.solver.track import frame_fit as ff
from articula.solver.tracking.pose_prior import PosePrior
from articula.solver.track.shape_prior import ShapePrior, lift
from articula.solver.geometry.normals import vertex_normals

from .arm_body import arm_body


def _frame(poses, n):
    return Poses(poses.rotations[n:n + 1], poses.translations[n:n + 1], poses.scales[n:n + 1])


@pytest.fixture(scope="module")
def tube_case():
    """A small tube body in two known poses, noisy full captures of it, and a state off the truth."""
    model = synthetic.tube_body(rings=6, segments=6)
    B = model.skeleton.num_bones
    rng = np.random.default_rng(0)
    poses = synthetic.random_poses(2, B, seed=2, max_angle=0.5, translation=0.1, scale_range=(1.0, 1.0))
    caps = [ff.Capture.from_mesh(p + rng.normal(scale=0.004, size=p.shape), model.faces)
            for p in hybrid_skin(model, poses)]
    x = model.rest_vertices + rng.normal(scale=0.003, size=model.rest_vertices.shape)
    heads = model.skeleton.heads.copy()
    heads[1:] += rng.normal(scale=0.01, size=(B - 1, 3))
    prior = PosePrior.from_poses(model.skeleton, synthetic.random_poses(10, B, seed=5, max_angle=0.6), k_max=2)
    train = synthetic.random_poses(5, B, seed=1, max_angle=0.6, translation=0.0, scale_range=(1.0, 1.0))
    opts = ad.AdaptOptions(w_shape=30.0, w_sym=10.0, w_tangent=5.0, joint_prior=0.1)
    ctx = ad._Context(model, caps, prior, ShapePrior.from_model(model, train), ad.mirror_pairs(model.skeleton), opts,
                      AnchorGroups(model))
    state = ad._State(x, heads, poses)
    m, g = ctx.at(state)
    pairs = [ff._refresh(m, g, _frame(poses, n), c, ctx.refresh) for n, c in enumerate(caps)]
    return ctx, state, pairs


def test_objective_gradient_matches_central_differences(tube_case):
    """T14: half the gradient g of the IRLS majoriser (data, shape, symmetry, pose prior, joint prior and
    tangential terms) equals half the derivative of the true objective Q (Charbonnier data term, pairs
    held) at the refresh point, for sampled rest-vertex coordinates, every joint centre and every free
    pose parameter."""
    ctx, state, pairs = tube_case
    H_xx, H_xs, H_ss, g_x, g_s, _ = ad._system(ctx, state, pairs)
    assert ctx.kappa > 0 and len(ctx.sym_pairs) == 5
    g = np.concatenate([g_x, g_s])
    rng = np.random.default_rng(1)
    cols = np.concatenate([rng.choice(len(g_x), 20, replace=False), len(g_x) + np.arange(len(g_s))])
    h = 1e-6

    def Q(step):
        return ctx.terms(ctx.moved(state, step, restore=False), pairs)["Q"]
    fd = np.array([(Q(h * e) - Q(-h * e)) / (2 * h) for e in np.eye(len(g))[cols]])
    assert np.abs(fd - 2 * g[cols]).max() < 1e-6 * np.abs(2 * g[cols]).max()
    for part in (slice(0, 20), slice(20, 20 + ctx.nh), slice(20 + ctx.nh, None)):   # each block matters
        assert np.abs(g[cols][part]).max() > 1e-8


def test_data_gauss_newton_blocks_match_central_differences(tube_case):
    """T14: the data term's blocks (data_terms lifted through the affine form and the joint Jacobian)
    equal JᵀSJ and JᵀSe with J the central-difference Jacobian of the pair residuals (point-to-plane
    rows along the capture normal) w.r.t. sampled rest-vertex coordinates and the joint centres."""
    ctx, state, pairs = tube_case
    model, groups = ctx.at(state)
    B, V = ctx.B, ctx.V
    one, p = _frame(state.poses, 0), pairs[0]
    plane = ff.plane_mask(p, "all")
    scale = np.random.default_rng(3).uniform(0.5, 2.0, len(p.distances))
    cols = {("head", b): 3 * (b - 1) for b in range(1, B)}
    posed, J = dense_jacobian(model, one, cols, 3 * (B - 1), groups, heads=True)
    H_p, b_p, used, value = ad.data_terms(p, posed[0], plane, scale)
    H_xx, H_xh, H_hh, g_x, g_h = lift(H_p, b_p, affine_form(model, one, groups)[0][0], J[0], used)

    def e(dx, dh):
        heads = state.heads.copy()
        heads[1:] += dh.reshape(-1, 3)
        m = ad.adapted_model(ctx.model, state.rest + dx.reshape(V, 3), heads)
        return (np.sqrt(scale)[:, None] * ff.pair_residuals(p, hybrid_skin(m, one)[0], plane)).ravel()
    rng = np.random.default_rng(4)
    vx = rng.choice(np.unique(p.vertex_ids), 8, replace=False)
    xcols = (3 * vx[:, None] + np.arange(3)).ravel()
    h, z_x, z_h = 1e-6, np.zeros(3 * V), np.zeros(3 * (B - 1))
    Jx = np.stack([(e(h * u, z_h) - e(-h * u, z_h)) / (2 * h) for u in np.eye(3 * V)[xcols]], axis=1)
    Jh = np.stack([(e(z_x, h * u) - e(z_x, -h * u)) / (2 * h) for u in np.eye(3 * (B - 1))], axis=1)
    r = e(z_x, z_h)
    assert np.isclose(value, r @ r, rtol=1e-10)
    for got, want in ((g_x[xcols], Jx.T @ r), (g_h, Jh.T @ r), (H_hh, Jh.T @ Jh), (H_xh[xcols], Jx.T @ Jh),
                      (H_xx[xcols][:, xcols].toarray(), Jx.T @ Jx)):
        assert np.abs(got - want).max() < 1e-6 * np.abs(want).max()


def test_schur_step_equals_the_dense_damped_solve(tube_case):
    """Eliminating the rest vertices gives the step of the full damped system, solved densely."""
    ctx, state, pairs = tube_case
    H_xx, H_xs, H_ss, g_x, g_s, D_s = ad._system(ctx, state, pairs)
    solver = ad.SchurSolver(H_xx, H_xs, H_ss, g_x, g_s, D_s)
    mu = 1e-2
    d = H_xx.diagonal()
    K = H_xx.toarray() + np.eye(len(d)) * ad.X_FLOOR * d.mean()
    full = np.block([[K, H_xs], [H_xs.T, H_ss + np.diag(mu * solver.D_s)]])
    want = np.linalg.solve(full, -np.concatenate([g_x, g_s]))
    got = solver.step(mu)
    assert np.abs(got - want).max() < 1e-7 * np.abs(want).max()


def test_gauge_leaves_every_posed_vertex_in_place():
    """fix_gauge: rest vertices and non-root joints move by −d (d = median displacement), the root
    translations take it up: posed vertices unchanged, median displacement 0."""
    model = synthetic.tube_body(rings=6, segments=6)
    rng = np.random.default_rng(5)
    poses = synthetic.random_poses(3, model.skeleton.num_bones, seed=2, max_angle=0.6, scale_range=(0.9, 1.1))
    x = model.rest_vertices + 0.01 + rng.normal(scale=0.003, size=model.rest_vertices.shape)
    heads = model.skeleton.heads + rng.normal(scale=0.01, size=model.skeleton.heads.shape)
    before = hybrid_skin(ad.adapted_model(model, x, heads), poses)
    x2, h2, poses2, d = ad.fix_gauge(model, x, heads, poses, model.rest_vertices)
    assert np.linalg.norm(d) > 0.01
    assert np.abs(hybrid_skin(ad.adapted_model(model, x2, h2), poses2) - before).max() < 1e-12
    assert np.allclose(np.median(x2 - model.rest_vertices, axis=0), 0.0, atol=1e-15)
    assert np.array_equal(h2[0], heads[0])


def test_symmetry_residuals_vanish_exactly_for_equal_mirror_lengths():
    """T15: Q^sym = 0 iff the mirror bones have equal lengths, for any bone directions; the Jacobian in the
    head layout matches central differences; restore_symmetry makes the lengths equal."""
    sk = arm_body().skeleton
    pairs = ad.mirror_pairs(sk)
    assert [(sk.names[a], sk.names[c]) for a, _, c, _ in pairs] == [
        ("shoulder.L", "shoulder.R"), ("upper_arm.L", "upper_arm.R"), ("forearm.L", "forearm.R")]
    rng = np.random.default_rng(6)
    heads = sk.heads.copy()
    for b in range(1, 5):                                # arbitrary left heads, the right ones mirrored
        heads[b] = rng.normal(scale=0.3, size=3)
        heads[b + 4] = heads[b] * [-1.0, 1.0, 1.0]
    r, J = ad.symmetry_terms(heads, sk, pairs)
    assert np.abs(r).max() < 1e-15
    moved = heads.copy()
    moved[3] += [0.0, 0.0, 0.02]
    r, J = ad.symmetry_terms(moved, sk, pairs)
    lengths = lambda hh, a, c: np.linalg.norm(hh[c] - hh[a])          # noqa: E731
    assert np.allclose(r, [lengths(moved, a, b) - lengths(moved, c, d) for a, b, c, d in pairs])
    assert np.abs(r).max() > 0.001
    h = 1e-7
    fd = np.stack([(ad.symmetry_terms(np.vstack([moved[:1], moved[1:] + h * u.reshape(-1, 3)]), sk, pairs)[0] -
                    ad.symmetry_terms(np.vstack([moved[:1], moved[1:] - h * u.reshape(-1, 3)]), sk, pairs)[0])
                   / (2 * h) for u in np.eye(3 * (sk.num_bones - 1))], axis=1)
    assert np.abs(fd - J).max() < 1e-7
    fixed = ad.restore_symmetry(moved, sk, pairs)
    assert np.abs(ad.symmetry_terms(fixed, sk, pairs)[0]).max() < 1e-12
    assert np.linalg.norm(fixed - moved) < 0.02


# --------------------------------------------------------------------------------- planted subject (T20)

def _subject(model, joint_offset, left_only=False):
    """The arm body with a 1 cm bulge (smooth, along the normals) on the left upper arm and the left and
    right shoulder and elbow joints moved by ``joint_offset`` (mirror images, or the left ones only)."""
    x0, sk = model.rest_vertices, model.skeleton
    prof = np.clip(1 - (np.linalg.norm(x0 - [0.30, -0.04, 1.41], axis=1) / 0.07) ** 2, 0, None) ** 2
    rest = x0 + 0.01 * prof[:, None] * vertex_normals(x0, model.faces)
    heads = sk.heads.copy()
    for name, o in (("upper_arm.L", (0.01, 0.012, -0.01)), ("forearm.L", (0.0, -0.015, 0.013))):
        o = joint_offset * np.array(o) / np.linalg.norm(o)
        heads[sk.names.index(name)] += o
        if not left_only:
            heads[sk.names.index(name[:-1] + "R")] += o * [-1.0, 1.0, 1.0]
    return ad.adapted_model(model, rest, heads), prof


def _scans(subject, poses, noise, hide=None):
    """4-view scans of the posed subject; ``hide (V,)`` bool: capture points nearest those subject
    vertices are dropped in every frame (an unobserved region)."""
    out = []
    for n, posed in enumerate(hybrid_skin(subject, poses)):
        rig = unregistered.ScanRig(outlier_fraction=0.0 if noise is NOISELESS else 0.002)
        pts, tris, _, _, cams = unregistered.scan_frame(posed, subject.faces, np.random.default_rng([0, n]), rig, noise)
        if hide is not None:
            from scipy.spatial import cKDTree
            keep = ~hide[cKDTree(posed).query(pts)[1]]
            index = np.cumsum(keep) - 1
            tris = index[tris[keep[tris].all(axis=1)]]
            pts = pts[keep]
        out.append(ff.Capture.from_mesh(pts, tris, cams))
    return out


@pytest.fixture(scope="module")
def arm_case():
    model = arm_body()
    B = model.skeleton.num_bones
    truth = synthetic.random_poses(4, B, seed=3, max_angle=0.8, translation=0.1, scale_range=(1.0, 1.0))
    rng = np.random.default_rng(7)
    start = Poses(quat_mul(truth.rotations, rotvec_to_quat(rng.normal(scale=0.02, size=(4, B, 3)))),
                  truth.translations + rng.normal(scale=0.003, size=(4, 3)), truth.scales.copy())
    train = synthetic.random_poses(8, B, seed=11, max_angle=0.8, translation=0.0, scale_range=(1.0, 1.0))
    return model, truth, start, train


def _errors(result, subject, heads_truth):
    err = np.linalg.norm(result.model.rest_vertices - subject.rest_vertices, axis=1) * 1e3
    jerr = np.linalg.norm(result.model.skeleton.heads - heads_truth, axis=1)[1:] * 1e3
    return err, jerr


def test_adaptation_recovers_a_planted_subject_from_exact_scans(arm_case):
    """T20: bulge and joint offsets recovered (surface median < 1 mm, joints < 5 mm) from exact scans of
    four known poses (start 1 deg per bone off); the right hand, never scanned, stays close to the template."""
    model, truth, start, train = arm_case
    subject, prof = _subject(model, 0.02)
    hand_r = subject.rest_vertices[:, 0] < -0.72
    caps = _scans(subject, truth, NOISELESS, hide=hand_r)
    result = ad.adapt_model(model, caps, start, options=ad.AdaptOptions(max_iterations=15), training_poses=train)
    err, jerr = _errors(result, subject, subject.skeleton.heads)
    assert np.median(err) < 1.0 and jerr.max() < 5.0
    assert np.median(err[prof > 0.5]) < 1.5                           # the bulge (6.3 mm on the template)
    assert np.median(err[hand_r]) < 2.0                               # unobserved: near the template (= truth)
    assert result.log["Q"].min() == result.log["Q"][np.argmin(result.log["Q"])] <= result.log["Q"][0]
    assert result.stats["sym_pairs"] == 3 and result.model.faces is model.faces


def test_adaptation_on_noisy_scans_improves_the_template(arm_case):
    """T20 with the scanner's noise (Kinect v1 model, 2.2-2.8 m, 0.2 % outliers): the planted bulge and
    joint offsets are partly recovered, and the model fits the scans better than the template."""
    model, truth, start, train = arm_case
    subject, prof = _subject(model, 0.02)
    caps = _scans(subject, truth, NoiseParams())
    result = ad.adapt_model(model, caps, start, options=ad.AdaptOptions(max_iterations=10), training_poses=train)
    err, jerr = _errors(result, subject, subject.skeleton.heads)
    err0 = np.linalg.norm(model.rest_vertices - subject.rest_vertices, axis=1) * 1e3
    print(f"noisy: surface median {np.median(err):.2f} mm, p90 {np.percentile(err, 90):.2f}, bulge "
          f"{np.median(err[prof > 0.5]):.2f} (template {np.median(err0[prof > 0.5]):.2f}), joints max "
          f"{jerr.max():.1f} mean {jerr.mean():.1f} mm")
    assert np.median(err[prof > 0.5]) < np.median(err0[prof > 0.5])
    assert np.percentile(err, 90) < 5.0
    assert result.log["data"][np.argmin(result.log["Q"])] < result.log["data"][0]


def test_symmetry_holds_after_adapting_to_an_asymmetric_subject(arm_case):
    """T15: with only the left joints moved, the mirror bones keep equal lengths (< 1e-4 mm)."""
    model, truth, start, train = arm_case
    subject, _ = _subject(model, 0.02, left_only=True)
    result = ad.adapt_model(model, _scans(subject, truth, NOISELESS), start,
                            options=ad.AdaptOptions(max_iterations=3), training_poses=train)
    sk = result.model.skeleton
    r, _ = ad.symmetry_terms(sk.heads, sk, ad.mirror_pairs(model.skeleton))
    assert np.abs(r).max() < 1e-7
    assert np.abs(sk.heads - model.skeleton.heads).max() > 0.002        # the joints did move


# --------------------------------------------------------------------------------- bad input, cancelling

def test_bad_input_is_refused(arm_case):
    model, truth, _, _ = arm_case
    pts = hybrid_skin(model, _frame(truth, 0))[0]
    cap = ff.Capture.from_mesh(pts, model.faces)
    with pytest.raises(ArticulaInputError, match="2 captures but 1 poses"):
        ad.adapt_model(model, [cap, cap], _frame(truth, 0))
    bad = dataclasses.replace(cap, points=np.where(np.arange(len(pts))[:, None] == 3, np.nan, pts))
    with pytest.raises(ArticulaInputError, match="non-finite"):
        ad.adapt_model(model, [bad], _frame(truth, 0))
    empty = ff.Capture(np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(ArticulaInputError, match="no points"):
        ad.adapt_model(model, [empty], _frame(truth, 0))
    with pytest.raises(ArticulaInputError, match="no key frames"):
        ad.adapt_model(model, [], Poses.identity(0, model.skeleton.num_bones))
    with pytest.raises(ArticulaInputError, match="w_shape"):
        ad.adapt_model(model, [cap], _frame(truth, 0), options=ad.AdaptOptions(w_shape=-1.0))
    with pytest.raises(ArticulaInputError, match="to_plane"):
        ad.adapt_model(model, [cap], _frame(truth, 0), options=ad.AdaptOptions(to_plane="sideways"))
    with pytest.raises(ArticulaInputError, match="pose_rotations"):
        ad.adapt_model(model, [cap], _frame(truth, 0), training_poses=Poses.identity(2, 3))


def test_cancel_leaves_the_model_untouched(arm_case):
    model, truth, _, _ = arm_case
    before = model.rest_vertices.copy(), model.skeleton.heads.copy()
    caps = [ff.Capture.from_mesh(p, model.faces) for p in hybrid_skin(model, truth)[:2]]
    calls = []

    def progress(fraction, text):
        calls.append((fraction, text))
        raise Cancelled()
    with pytest.raises(Cancelled):
        ad.adapt_model(model, caps, Poses(truth.rotations[:2], truth.translations[:2], truth.scales[:2]),
                       progress=progress)
    assert len(calls) == 1 and "update 1" in calls[0][1]
    assert np.array_equal(model.rest_vertices, before[0]) and np.array_equal(model.skeleton.heads, before[1])
