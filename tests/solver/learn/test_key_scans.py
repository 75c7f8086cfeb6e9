"""Key-scan selection (solver.learn.key_scans) and learn_rig from key scans with the other scans' poses fitted."""
import numpy as np
import pytest

from articula.solver.learn.key_scans import TIME_KEY_SCANS, aligned_features, select_key_scans, time_budget_count
from articula.solver.learn.pipeline import learn_rig
from articula.solver.rig.model import Poses
from articula.solver.fit.pose_fit import fit_poses
from articula.solver.rig.skinning import hybrid_skin

from articula.sample_scenes.tube_scans import hybrid_truth, random_rigid_poses


def _rigidly_moved(scans, seed=3):
    R, t = random_rigid_poses(len(scans), seed, max_angle=2.5)
    return np.einsum("mij,mvj->mvi", R[:, 0], scans) + t[:, None]


def _brute_force_fps(scans, count, first):
    """Greedy farthest-point sampling written out: recompute every scan's distance to its nearest key."""
    f = aligned_features(scans, first)
    D = np.linalg.norm(f[:, None] - f[None], axis=2)
    keys = [first]
    while len(keys) < count:
        rest = [m for m in range(len(scans)) if m not in keys]
        keys.append(max(rest, key=lambda m: D[m, keys].min()))
    return sorted(keys)


def test_selection_matches_brute_force_and_includes_first():
    _, _, scans = hybrid_truth(14, seed=2)
    for first, count in ((0, 5), (6, 4), (13, 9)):
        keys = select_key_scans(scans, count, first)
        assert keys.tolist() == _brute_force_fps(scans, count, first)
        assert first in keys and len(np.unique(keys)) == count and np.all(np.diff(keys) > 0)


def test_selection_ignores_rigid_motion_and_takes_all_when_few():
    _, _, scans = hybrid_truth(12, seed=4)
    assert np.array_equal(select_key_scans(scans, 5, 2), select_key_scans(_rigidly_moved(scans), 5, 2))
    assert np.array_equal(select_key_scans(scans, 12), np.arange(12))
    assert np.array_equal(select_key_scans(scans, 40), np.arange(12))
    with pytest.raises(ValueError, match="count"):
        select_key_scans(scans, 0)


def test_selection_covers_distinct_poses_never_repeats_duplicates():
    _, _, scans = hybrid_truth(3, seed=5)
    many = np.repeat(scans, 5, axis=0)                       # 15 scans: 3 poses, 5 identical copies each
    keys = select_key_scans(many, 3, first=0)
    assert sorted(k // 5 for k in keys) == [0, 1, 2]           # one copy of every pose
    same = np.repeat(scans[:1], 6, axis=0)
    assert len(np.unique(select_key_scans(same, 4))) == 4


@pytest.fixture(scope="module")
def from_keys():
    model, poses, scans = hybrid_truth(12, seed=1)
    kw = dict(parts=8, max_iterations=1, bcd_sweeps=2, gn_iterations=3, bcd_steps=(0.2, 0.05), rest_scan=0)
    res = learn_rig(scans, model.faces, key_scans=6, **kw)
    return scans, res, kw


def test_key_scan_learning_equals_learning_on_the_keys(from_keys):
    scans, res, kw = from_keys
    keys = np.asarray(res.report["key_scans"])
    assert len(keys) == 6 and 0 in keys and res.report["rest_scan"] == 0
    alone = learn_rig(scans[keys], res.model.faces, key_scans=None, **kw)
    assert np.allclose(alone.model.rest_vertices, res.model.rest_vertices, atol=1e-12)
    assert np.array_equal(alone.model.swing_weights, res.model.swing_weights)
    assert np.allclose(alone.poses.rotations, res.poses.rotations[keys], atol=1e-12)
    assert res.report["objective_log"] == alone.report["objective_log"]


def test_too_few_key_scans_refused(from_keys):
    from articula.solver.errors import ArticulaInputError
    scans, res, _ = from_keys
    for bad in (2, -1):
        with pytest.raises(ArticulaInputError, match="key_scans"):
            learn_rig(scans, res.model.faces, parts=8, key_scans=bad)


def test_other_scans_get_fitted_poses_as_good_as_the_keys(from_keys):
    scans, res, _ = from_keys
    keys = np.asarray(res.report["key_scans"])
    others = np.setdiff1d(np.arange(len(scans)), keys)
    assert len(res.poses) == len(scans) and res.report["other_scans"]["scans"] == len(others)
    res.poses.validate(8)
    err = np.linalg.norm(hybrid_skin(res.model, res.poses) - scans, axis=2)
    rms = np.sqrt((err ** 2).mean(axis=1))
    assert rms[others].max() < 1e-3          # metres, on a 1.7 m body: close to the training scans' 0.3 mm
    # near the fixed model's optimum: a fully converged fit from there gains little
    sub = Poses(res.poses.rotations[others], res.poses.translations[others], res.poses.scales[others])
    full = fit_poses(res.model, scans[others], init=sub, max_iterations=50, tol=1e-14)
    assert np.all(np.sqrt(full.energy / scans.shape[1]) > 0.95 * rms[others])
    assert res.report["surface_error_mm"]["count"] == scans.shape[0] * scans.shape[1]
    assert "other_scans" in res.report["timings_s"]


def test_time_budget_cuts_key_scans_of_large_meshes_only():
    assert time_budget_count(5_000, 40, 300_000) == 40                 # small mesh: as asked
    assert time_budget_count(13_380, 40, 300_000) == 22                # 300,000 / 13,380
    assert time_budget_count(53_514, 40, 300_000) == TIME_KEY_SCANS    # never below the floor
    assert time_budget_count(53_514, 12, 300_000) == 12                # never above the request
    assert time_budget_count(53_514, 0, 300_000) == 0                  # every scan, asked for
    assert time_budget_count(53_514, 40, 0) == 40                      # no budget


def test_learning_under_a_time_budget_says_so():
    """24 scans of the tube with a budget of 5 scans' worth: the floor of 20 key scans, the other 4 fitted,
    and the report's note says why; without a budget all 24 are learned from."""
    model, _, scans = hybrid_truth(M=24, seed=4)
    V = scans.shape[1]
    res = learn_rig(scans, model.faces, parts=8, max_iterations=0, key_scan_budget=V * 5)
    assert len(res.report["key_scans"]) == TIME_KEY_SCANS and res.report["other_scans"]["scans"] == 4
    assert "learned from 20 of 24 scans" in res.report["key_scans_note"]
    res = learn_rig(scans, model.faces, parts=8, max_iterations=0, key_scan_budget=0)
    assert len(res.report["key_scans"]) == 24 and "key_scans_note" not in res.report
