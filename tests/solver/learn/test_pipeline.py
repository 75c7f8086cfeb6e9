"""learn_rig end to end (G1, G14) and its refusal of bad input."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError, Cancelled
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.learn.pipeline import learn_rig
from articula.solver.rig.skinning import hybrid_skin

from articula.sample_scenes.tube_scans import JOINTS, PARTS, TAILS, body, hybrid_truth, rigid_scans


@pytest.fixture(scope="module")
def learned():
    model, poses, scans = hybrid_truth(6, seed=1)
    calls = []
    res = learn_rig(scans, model.faces, parts=8, max_iterations=2, bcd_sweeps=2, gn_iterations=3,
                    bcd_steps=(0.2, 0.05), progress=lambda f, s, o: calls.append((f, s, o)))
    return model, scans, res, calls, poses


def test_result_shapes_and_validity(learned):
    truth, scans, res, *_ = learned
    res.model.validate()
    res.poses.validate(8)
    assert len(res.poses) == len(scans) and res.model.num_vertices == truth.num_vertices
    assert np.array_equal(res.model.faces, truth.faces)
    for key in ("mean", "std", "median", "mad", "iqr"):
        assert np.isfinite(res.report["surface_error_mm"][key])
    assert set(res.report["timings_s"]) >= {"initialisation", "joints_and_poses", "weights", "rest_vertices"}
    # a scan vertex is never farther from the posed surface than from its own posed vertex
    assert res.report["surface_error_mm"]["mean"] <= res.report["vertex_rms_mm"] + 1e-9
    assert res.report["surface_error_mm"]["count"] == scans.shape[0] * scans.shape[1]


def test_objective_monotone_and_fit_improves(learned):
    truth, scans, res, calls, _ = learned
    log = [e for _, e in res.report["objective_log"]]
    assert all(b <= a * (1 + 1e-12) for a, b in zip(log, log[1:]))
    assert log[-1] < 0.2 * res.report["initial_objective"]
    assert log[0] <= res.report["initial_objective"]          # a warm start is kept only if it lowers E at α
    objs = [o for _, _, o in calls if o is not None]
    assert all(b <= a * (1 + 1e-9) for a, b in zip(objs, objs[1:]))          # progress never increases
    fr = [f for f, _, _ in calls]
    assert all(b >= a - 1e-12 for a, b in zip(fr, fr[1:])) and fr[-1] <= 1.0
    posed = hybrid_skin(res.model, res.poses)
    assert np.sqrt(np.mean(np.sum((posed - scans) ** 2, axis=2))) * 1e3 == pytest.approx(res.report["vertex_rms_mm"])
    assert res.report["surface_error_mm"]["mean"] < 3.0                        # mm, body ~1.7 m tall


def _joint_errors(truth, poses, res):
    """Distance of every learned joint to the nearest true joint, relative to that true bone's length.
    The learned rest mesh is the (posed) rest scan, so the true joints are moved into that scan."""
    Rm, tm = forward_kinematics(truth.skeleton, poses)
    r = res.report["rest_scan"]
    par = np.maximum(truth.skeleton.parents, 0)
    joints = np.einsum("bij,bj->bi", Rm[r, par], JOINTS) + tm[r, par]
    rel = []
    for b in range(1, 8):
        d = np.linalg.norm(joints[1:] - res.model.skeleton.heads[b], axis=1)
        g = 1 + int(np.argmin(d))
        rel.append(d[g - 1] / np.linalg.norm(TAILS[g] - JOINTS[g]))
    return np.array(rel)


def test_initial_joints_within_5_percent_on_hybrid_data():
    truth, poses, scans = hybrid_truth(6, seed=1)
    res = learn_rig(scans, truth.faces, parts=8, max_iterations=0)
    assert _joint_errors(truth, poses, res).max() < 0.05


def test_learned_joints_stay_close_to_truth(learned):
    """With the joint warm-up round the joints stay near the true centres (without it: up to 7.5 %)."""
    truth, scans, res, _, poses = learned
    assert _joint_errors(truth, poses, res).max() < 0.05


def test_stiff_joint_prior_keeps_the_initial_joints():
    """joint_prior (ρ) enters E: with a huge ρ the joints stay at their initial estimates, E stays monotone."""
    truth, poses, scans = hybrid_truth(4, seed=2)
    kw = dict(parts=8, seed=0, rest_scan=0, symmetry=False)     # λ = 1e10 would outweigh any prior
    start = learn_rig(scans, truth.faces, max_iterations=0, **kw).model.skeleton.heads
    res = learn_rig(scans, truth.faces, max_iterations=2, bcd_sweeps=1, gn_iterations=2, joint_warmup_rounds=0,
                    warm_start=(), joint_prior=1e9, **kw)
    log = [e for _, e in res.report["objective_log"]]
    assert all(b <= a * (1 + 1e-12) for a, b in zip(log, log[1:]))
    assert np.abs(res.model.skeleton.heads - start).max() < 1e-6
    free = learn_rig(scans, truth.faces, max_iterations=2, bcd_sweeps=1, gn_iterations=2, joint_warmup_rounds=0,
                     warm_start=(), joint_prior=0.0, **kw)
    assert np.abs(free.model.skeleton.heads - start).max() > 1e-4


def test_deterministic_under_seed():
    model, poses, scans = hybrid_truth(4, seed=2)
    kw = dict(parts=8, max_iterations=1, bcd_sweeps=1, gn_iterations=1, bcd_steps=(0.2,), seed=3)
    a = learn_rig(scans, model.faces, **kw)
    b = learn_rig(scans, model.faces, **kw)
    assert a.report["rest_scan"] == b.report["rest_scan"]
    assert np.array_equal(a.model.rest_vertices, b.model.rest_vertices)
    assert np.array_equal(a.poses.rotations, b.poses.rotations)


def test_cancel_from_progress():
    model, poses, scans = hybrid_truth(4)

    def cancel(f, s, o):
        if f > 0.15:
            raise Cancelled()
    with pytest.raises(Cancelled):
        learn_rig(scans, model.faces, parts=8, max_iterations=2, progress=cancel)


def test_bad_input_refused():
    scans, faces, labels, rest, _, _ = rigid_scans(5)
    with pytest.raises(ArticulaInputError, match="at least 3"):
        learn_rig(scans[:2], faces, parts=8)
    bad = scans.copy()
    bad[2, 7, 1] = np.nan
    with pytest.raises(ArticulaInputError, match="scan 2, vertex 7"):
        learn_rig(bad, faces, parts=8)
    with pytest.raises(ArticulaInputError, match="topology"):
        learn_rig(scans[:, :-5], faces, parts=8)
    with pytest.raises(ArticulaInputError, match="shape"):
        learn_rig(scans[..., :2], faces, parts=8)
    # two islands: a second copy of the body, shifted
    V = scans.shape[1]
    two = np.concatenate([scans, scans + [2.0, 0, 0]], axis=1)
    with pytest.raises(ArticulaInputError, match="disconnected"):
        learn_rig(two, np.concatenate([faces, faces + V]), parts=8)
    # no motion: the scans are rigid copies of one another
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(5, 3, 3)))[0]
    R *= np.sign(np.linalg.det(R))[:, None, None]
    rigid = np.einsum("mij,vj->mvi", R, rest)
    with pytest.raises(ArticulaInputError, match="rigid motion"):
        learn_rig(rigid, faces, parts=8)


def test_more_parts_than_motion_refused():
    scans, faces, labels, rest, Rm, tm = rigid_scans(6)
    # the left elbow never bends: forearm.L moves with upper_arm.L -> only 7 separable parts
    still = labels == 3
    scans[:, still] = np.einsum("mij,vj->mvi", Rm[:, 2], rest[still]) + tm[:, 2][:, None]
    with pytest.raises(ArticulaInputError, match="parts"):
        learn_rig(scans, faces, parts=8, max_iterations=1)


def test_huge_input_refused_up_front_with_memory_estimate():
    """Refused from the sizes alone, before the scans are converted or scanned (a 2,000 x 202,500 x 3 view
    of one frame would need 9.7 GB as float64 and 1.2 GB for the finite check alone)."""
    n = 450                                              # 202,500-vertex grid
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1) * 0.01
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    scans = np.broadcast_to(verts, (2000, n * n, 3))
    with pytest.raises(ArticulaInputError, match=r"2000 scans x 202500 vertices with 19 parts need up to .* GB "
                                                 r"of memory even when learning from only 3 key scans, over the "
                                                 r"memory limit of 4 GB: use fewer parts, decimate"):
        learn_rig(scans, faces, parts=19, key_scans=0, memory_limit_gb=4)


def test_initial_skeleton_is_used_as_given():
    from articula.sample_scenes.tube_scans import truth_skeleton
    scans, faces, labels, rest, _, _ = rigid_scans(5)
    sk = truth_skeleton()
    res = learn_rig(scans, faces, initial_skeleton=sk, max_iterations=0, rest_scan=0)   # scan 0 = rest pose
    assert res.model.skeleton.names == sk.names and res.report["rest_scan"] == 0
    assert np.array_equal(res.model.skeleton.heads, sk.heads)
    res.model.validate()
    assert res.report["parts"] == 8
    # rigid data, true joints, nearest-bone parts (wrong near the seams, which biases the part fits)
    err = np.linalg.norm(hybrid_skin(res.model, res.poses) - scans, axis=2)
    assert err[0].max() < 1e-9                                     # the rest scan itself: identity poses
    assert np.median(err) < 0.01


def test_number_of_parts_chosen_automatically():
    scans, faces, labels, rest, _, _ = rigid_scans(6, seed=2)
    res = learn_rig(scans, faces, max_iterations=0, k_max=10)
    assert res.report["parts"] == 8 and res.model.skeleton.num_bones == 8
    assert len(res.report["k_curve_mm"]) == 10
    assert len(res.report["mirror_pairs"]) == 3
