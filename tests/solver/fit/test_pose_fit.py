"""Per-frame pose fitting of a fixed model (solver.fit.pose_fit) against known synthetic poses."""
import numpy as np
import pytest

from articula.solver.rig import jacobians
from articula.solver.fit import pose_fit
from articula.solver.rig import skinning
from articula.sample_scenes import synthetic
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.model import Poses
from articula.solver.geometry.rotations import quat_conj, quat_mul, rotvec_to_quat


@pytest.fixture(scope="module")
def model():
    m = synthetic.random_model(600, seed=3)
    m.validate()
    return m


def perturb(poses, degrees, seed, shift=0.03, scale=0.03):
    """Every bone turned by ``degrees`` about a random axis, the root moved by ``shift`` m per axis and the
    scale changed by the factor 1 ± ``scale``."""
    rng = np.random.default_rng(seed)
    N, B = poses.rotations.shape[:2]
    axis = rng.normal(size=(N, B, 3))
    axis /= np.linalg.norm(axis, axis=2, keepdims=True)
    q = quat_mul(poses.rotations, rotvec_to_quat(np.radians(degrees) * axis))
    return Poses(q, poses.translations + rng.choice([-shift, shift], (N, 3)),
                 poses.scales * (1 + rng.choice([-scale, scale], N)))


def angle_errors(q_fit, q_true):
    """Rotation angle (radians) between corresponding quaternions (sign-independent; atan2 form, accurate
    near 0 where arccos is not)."""
    d = quat_mul(quat_conj(q_true), q_fit)
    return 2 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def test_recovers_random_poses_from_20_degree_start(model):
    truth = synthetic.random_poses(4, 19, seed=11)
    targets = skinning.hybrid_skin(model, truth)
    start = perturb(truth, 20.0, seed=1)
    assert angle_errors(start.rotations, truth.rotations).min() > np.radians(19.9)   # every bone is off
    fit = pose_fit.fit_poses(model, targets, init=start, fit_scale=True)
    assert fit.converged.all()
    assert angle_errors(fit.poses.rotations, truth.rotations).max() < 1e-6
    assert np.abs(fit.poses.translations - truth.translations).max() < 1e-6
    assert np.abs(fit.poses.scales - truth.scales).max() < 1e-6
    assert fit.rms.max() < 1e-8 and fit.vertex_errors.shape == (4, 600)


def test_procrustes_start_recovers_poses_without_a_guess(model):
    truth = synthetic.random_poses(3, 19, seed=12, scale_range=(1.0, 1.0))
    fit = pose_fit.fit_poses(model, skinning.hybrid_skin(model, truth))
    assert angle_errors(fit.poses.rotations, truth.rotations).max() < 1e-6
    assert np.abs(fit.poses.translations - truth.translations).max() < 1e-6


def test_procrustes_init_is_exact_for_a_rigid_model(model):
    rigid = synthetic.random_model(600, seed=3)
    rigid.twist_weights[:] = 0
    rigid.swing_weights[:] = 0
    truth = synthetic.random_poses(3, 19, seed=13, scale_range=(1.0, 1.0))
    init = pose_fit.procrustes_init(rigid, skinning.hybrid_skin(rigid, truth))
    assert angle_errors(init.rotations, truth.rotations).max() < 1e-9
    assert np.abs(init.translations - truth.translations).max() < 1e-9


def test_gradient_matches_finite_differences_and_the_step_decreases_the_objective(model):
    truth = synthetic.random_poses(1, 19, seed=14)
    targets = skinning.hybrid_skin(model, truth)
    start = perturb(truth, 20.0, seed=2)
    H, g, E = pose_fit.normal_equations(model, start, targets, fit_scale=True)
    from articula.solver.rig.jacobians import apply_pose_increment

    def energy(delta):
        p = apply_pose_increment(start, delta[None])
        r = skinning.hybrid_skin(model, p) - targets
        return np.sum(r * r)

    P = H.shape[1]
    h = 1e-6
    fd = np.array([(energy(h * e) - energy(-h * e)) / (2 * h) for e in np.eye(P)])
    assert np.abs(2 * g[0] - fd).max() < 1e-5 * np.abs(fd).max()
    step = np.linalg.solve(H[0] + 1e-3 * np.diag(np.diag(H[0])), -g[0])
    assert energy(step) < 0.5 * E[0]
    assert energy(-step) > E[0]               # the sign matters: the test can fail


def test_normal_equations_equal_the_dense_einsum_reference(model):
    """normal_equations (summed over anchor groups from factored Jacobians, residual as an extra
    column) = JᵀWJ, JᵀWr and rᵀWr by einsum on the dense Jacobian."""
    truth = synthetic.random_poses(3, 19, seed=15)
    targets = skinning.hybrid_skin(model, truth)
    start = perturb(truth, 20.0, seed=4)
    w = np.random.default_rng(5).uniform(0.0, 2.0, model.num_vertices)
    H, g, E = pose_fit.normal_equations(model, start, targets, vertex_weights=w, fit_scale=True)
    posed, J = jacobians.pose_jacobian(model, start)
    r = posed - targets
    H_ref = np.einsum("nvip,v,nviq->npq", J, w, J)
    g_ref = np.einsum("nvip,v,nvi->np", J, w, r)
    E_ref = np.einsum("nvi,v,nvi->n", r, w, r)
    assert np.abs(H - H_ref).max() < 1e-11 * np.abs(H_ref).max()
    assert np.abs(g - g_ref).max() < 1e-11 * np.abs(g_ref).max()
    assert np.abs(E - E_ref).max() < 1e-11 * E_ref.max()
    H2, g2, _ = pose_fit.normal_equations(model, start, targets)           # unweighted, scale fixed
    keep = np.ones(J.shape[-1], dtype=bool)
    keep[3] = False
    H2_ref = np.einsum("nvip,nviq->npq", J, J)[:, keep][:, :, keep]
    assert np.abs(H2 - H2_ref).max() < 1e-11 * np.abs(H2_ref).max()
    assert np.abs(g2 - np.einsum("nvip,nvi->np", J, r)[:, keep]).max() < 1e-11 * np.abs(g_ref).max()


def test_noise_robustness():
    """Spec T16: 5 mm noise, 20° perturbed start -> joint angles < 2°, translation < 2 mm.  The fit must also
    reach at least the objective of the true pose (no local minimum) and leave the noise as residual."""
    dense = synthetic.random_model(3000, seed=5)
    truth = synthetic.random_poses(3, 19, seed=15, scale_range=(1.0, 1.0))
    clean = skinning.hybrid_skin(dense, truth)
    targets = clean + np.random.default_rng(0).normal(scale=0.005, size=clean.shape)
    fit = pose_fit.fit_poses(dense, targets, init=perturb(truth, 20.0, seed=3, scale=0.0))
    assert np.degrees(angle_errors(fit.poses.rotations, truth.rotations)).max() < 2.0
    assert np.abs(fit.poses.translations - truth.translations).max() < 0.002
    assert np.all(fit.energy <= np.sum((clean - targets) ** 2, axis=(1, 2)))
    assert abs(fit.rms.mean() - 0.005 * np.sqrt(3)) < 0.0005


def test_turns_through_180_degrees(model):
    """A bone turned by 175°, started 20° away on the far side of 180°; and a sequence whose forearm turns
    from 150° to 210° in 15° steps about a fixed axis, fitted frame after frame."""
    B = 19
    axis = np.array([0.3, 0.9, -0.3]) / np.linalg.norm([0.3, 0.9, -0.3])
    truth = Poses.identity(1, B)
    truth.rotations[0, 9] = rotvec_to_quat(np.radians(175.0) * axis)
    truth.rotations[0, 13] = rotvec_to_quat(np.radians(178.0) * axis[[1, 0, 2]])
    targets = skinning.hybrid_skin(model, truth)
    start = Poses.identity(1, B)
    start.rotations[0, 9] = rotvec_to_quat(np.radians(195.0) * axis)       # = -165° about the axis
    start.rotations[0, 13] = rotvec_to_quat(np.radians(160.0) * axis[[1, 0, 2]])
    fit = pose_fit.fit_poses(model, targets, init=start)
    assert angle_errors(fit.poses.rotations, truth.rotations).max() < 1e-6

    angles = np.radians(np.linspace(150.0, 210.0, 5))
    seq = Poses.identity(len(angles), B)
    seq.rotations[:, 9] = rotvec_to_quat(angles[:, None] * axis)
    seq.translations[:] = np.linspace(0, 0.3, len(angles))[:, None]
    fit = pose_fit.fit_poses(model, skinning.hybrid_skin(model, seq), init="previous")
    assert angle_errors(fit.poses.rotations, seq.rotations).max() < 1e-6


def test_vertex_weights_ignore_corrupted_vertices(model):
    truth = synthetic.random_poses(1, 19, seed=16, scale_range=(1.0, 1.0))
    targets = skinning.hybrid_skin(model, truth)
    bad = np.arange(0, 600, 7)
    targets[:, bad] += 0.5                                                 # gross outliers
    w = np.ones(600)
    w[bad] = 0
    fit = pose_fit.fit_poses(model, targets, init=perturb(truth, 20.0, seed=4, scale=0.0), vertex_weights=w)
    assert angle_errors(fit.poses.rotations, truth.rotations).max() < 1e-6
    assert fit.rms.max() < 1e-8                                            # weighted RMS
    assert fit.vertex_errors[:, bad].min() > 0.4                           # unweighted per-vertex errors
    plain = pose_fit.fit_poses(model, targets, init=perturb(truth, 20.0, seed=4, scale=0.0), max_iterations=10)
    assert angle_errors(plain.poses.rotations, truth.rotations).max() > 1e-3   # without weights: pulled off


def test_bad_input(model):
    truth = synthetic.random_poses(2, 19, seed=17)
    targets = skinning.hybrid_skin(model, truth)
    with pytest.raises(ArticulaInputError, match=r"targets: expected shape \(N, 600, 3\)"):
        pose_fit.fit_poses(model, targets[:, :500])
    nan = targets.copy()
    nan[1, 42, 0] = np.nan
    with pytest.raises(ArticulaInputError, match="frame 1, vertex 42"):
        pose_fit.fit_poses(model, nan)
    with pytest.raises(ArticulaInputError, match="init"):
        pose_fit.fit_poses(model, targets, init="zero")
    with pytest.raises(ArticulaInputError, match="init: 1 poses for 2"):
        pose_fit.fit_poses(model, targets, init=Poses.identity(1, 19))
    with pytest.raises(ArticulaInputError, match="vertex_weights"):
        pose_fit.fit_poses(model, targets, vertex_weights=np.zeros(600))


def test_procrustes_start_without_root_vertices(model):
    """A root part with no vertex (as MakeHuman's floor-level ``Root`` bone): the root starts from the
    best-supported part and the fit still recovers the pose."""
    from articula.solver.rig.model import Model
    keep = model.anchor != 0
    rootless = Model(model.rest_vertices[keep], model.faces, model.skeleton, model.anchor[keep],
                     model.twist_weights[keep], model.swing_weights[keep])
    truth = synthetic.random_poses(2, 19, seed=18, scale_range=(1.0, 1.0))
    fit = pose_fit.fit_poses(rootless, skinning.hybrid_skin(rootless, truth))
    assert angle_errors(fit.poses.rotations, truth.rotations).max() < 1e-6


def test_normal_equations_are_built_once_per_iteration_that_runs(model, monkeypatch):
    """k LM iterations need k systems (the start and every accepted step but the last); 0 iterations none
    and leave the start and its energy; each further iteration lowers the energy."""
    truth = synthetic.random_poses(3, 19, seed=13)
    targets = skinning.hybrid_skin(model, truth)
    start = perturb(truth, 10.0, seed=2)
    calls = []
    original = pose_fit._Problem.system
    monkeypatch.setattr(pose_fit._Problem, "system", lambda self, p, idx: calls.append(len(idx)) or
                        original(self, p, idx))
    fits = {}
    for k in (0, 1, 2):
        calls.clear()
        fits[k] = pose_fit.fit_poses(model, targets, init=start, max_iterations=k, tol=0.0)
        assert len(calls) == k and sum(calls) <= 3 * k
    assert angle_errors(fits[0].poses.rotations, start.rotations).max() < 1e-9
    r0 = skinning.hybrid_skin(model, start) - targets
    E0 = np.einsum("nvi,nvi->n", r0, r0)
    assert np.allclose(fits[0].energy, E0, rtol=1e-12) and not fits[0].converged.any()
    assert (fits[1].energy < fits[0].energy).all() and (fits[2].energy < fits[1].energy).all()
