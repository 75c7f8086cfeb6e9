"""The automatic part count (solver.learn.part_count): the articulation test on point sets with known
motion, and the whole count on bodies whose true segments are known."""
import numpy as np
import pytest

from articula.solver.learn.part_count import (SPLIT_ANGLE_DEG, articulated_parts, relative_angles_deg,
                                              trial_split)
from articula.solver.learn.segmentation import (Clustering, Mesh, Sample, centred, choose_num_parts, moments,
                                               part_errors)

from articula.sample_scenes.tube_scans import hybrid_truth, rigid_scans


def _rot(axis, angle):
    """Rotation matrix about a unit ``axis`` by ``angle`` radians (Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _box(lo, hi, n):
    g = [np.linspace(lo[i], hi[i], n[i]) for i in range(3)]
    return np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 3)


def _global(rng, M):
    return [(_rot(rng.normal(size=3), rng.uniform(0, np.pi)), rng.normal(size=3)) for _ in range(M)]


def _one_part(rest, scans):
    """A 1-part clustering of every point (weight 1)."""
    rest, scans = centred(rest, scans)
    traj = scans.transpose(1, 0, 2).reshape(len(rest), -1)
    sample = Sample(moments(rest, scans), np.ones(len(rest)), traj, len(scans))
    return Clustering(sample, np.zeros(len(rest), dtype=np.int64), 1)


def _trial(rest, scans, seed=0):
    cl = _one_part(rest, scans)
    return trial_split(cl, 0, part_errors(cl)[0], np.random.default_rng(seed))


def test_relative_angle_of_two_rotations():
    R_a = np.stack([_rot([1, 2, 3], 0.3)] * 2)
    R_b = np.stack([R_a[0] @ _rot([0, 0, 1], np.radians(25)), R_a[1]])
    assert np.allclose(relative_angles_deg(R_a, R_b), [25, 0], atol=1e-6)


def test_two_rigid_halves_are_an_articulation():
    """A bar whose halves turn 20-40 degrees against each other: the split removes all error and its
    angle is the true one's 90th percentile."""
    rng = np.random.default_rng(0)
    rest = _box([-1, -0.1, -0.1], [1, 0.1, 0.1], [40, 5, 5])
    angles = rng.uniform(np.radians(20), np.radians(40), 12)
    scans = []
    for (G, g), a in zip(_global(rng, 12), angles):
        local = np.where(rest[:, :1] > 0, rest @ _rot([0, 0, 1], a).T, rest)
        scans.append(local @ G.T + g)
    trial = _trial(rest, np.array(scans))
    assert trial.gain > 0.99
    assert abs(trial.angle_deg - np.percentile(np.degrees(angles), 90)) < 0.5
    assert sorted(np.round(trial.halves)) == [500, 500]
    assert trial.qualifies(min_half=10)


def test_noise_on_a_rigid_body_is_not_an_articulation():
    rng = np.random.default_rng(1)
    rest = _box([-1, -0.2, -0.2], [1, 0.2, 0.2], [30, 6, 6])
    scans = np.array([rest @ G.T + g + rng.normal(scale=0.002, size=rest.shape) for G, g in _global(rng, 10)])
    trial = _trial(rest, scans)
    assert trial.angle_deg < SPLIT_ANGLE_DEG / 3
    assert not trial.qualifies(min_half=10)


def test_a_half_on_a_line_is_not_determined():
    """A few points on a line turning on their own fit any rotation about the line: refused."""
    rng = np.random.default_rng(2)
    body = _box([-1, -0.2, -0.2], [0, 0.2, 0.2], [20, 5, 5])
    line = np.c_[np.linspace(0.1, 0.5, 8), np.zeros(8), np.zeros(8)]
    rest = np.vstack([body, line])
    scans = []
    for G, g in _global(rng, 10):
        moved = np.vstack([body, line @ _rot(rng.normal(size=3), 0.8).T])
        scans.append(moved @ G.T + g)
    trial = _trial(rest, np.array(scans))
    assert not trial.determined and not trial.qualifies(min_half=1)


def _body_with_foot(M=16, seed=3):
    """Torso, a long leg swinging +-60 degrees and a small foot turning +-25 degrees on it (points, metres):
    rest (P,3), scans (M,P,3) and the true labels (P,) 0/1/2."""
    rng = np.random.default_rng(seed)
    torso = _box([-1.0, -0.3, -0.3], [0, 0.3, 0.3], [24, 12, 12])
    leg = _box([0.02, -0.1, -0.1], [1.6, 0.1, 0.1], [40, 5, 5])
    foot = _box([1.62, -0.08, -0.08], [1.7, 0.08, 0.12], [3, 4, 5])
    rest = np.vstack([torso, leg, foot])
    labels = np.repeat([0, 1, 2], [len(torso), len(leg), len(foot)])
    knee, ankle = np.zeros(3), np.array([1.61, 0, 0])
    scans = []
    for G, g in _global(rng, M):
        R1 = _rot([0, 0, 1], rng.uniform(-1.05, 1.05))
        R2 = R1 @ _rot([0, 1, 0], rng.uniform(-0.4, 0.4))
        x = rest.copy()
        x[labels == 1] = (rest[labels == 1] - knee) @ R1.T + knee
        a1 = (ankle - knee) @ R1.T + knee
        x[labels == 2] = (rest[labels == 2] - ankle) @ R2.T + a1
        scans.append(x @ G.T + g)
    return rest, np.array(scans), labels


def test_a_small_segment_found_after_the_curve_stops():
    """The foot carries under 3 % of the one-part error, so the curve stops at 2 parts; the articulation
    phase splits it off: 3 parts, matching the true segments."""
    rest, scans, labels = _body_with_foot()
    k0, _ = choose_num_parts(rest, scans, None, k_max=6)
    assert k0 == 2
    cl, info = articulated_parts(*centred(rest, scans), None, k_max=6)
    assert info["curve_parts"] == 2 and info["parts"] == 3 == cl.k
    assert len(info["splits"]) == 1 and info["splits"][0]["gain"] > 0.9
    assert "no part" in info["reason"]
    # every true segment is one learned part (each point to the part whose motion fits it best)
    got = np.argmin(Mesh(*centred(rest, scans)).errors(cl.R, cl.t), axis=1)
    for part in range(3):
        assert np.mean(got[labels == part] == np.bincount(got[labels == part]).argmax()) > 0.97


@pytest.mark.parametrize("seed", [0, 1])
def test_smooth_skin_adds_no_parts(seed):
    """Hybrid-skinned tube (8 bones, smooth joints): the blend zones are not articulations, so the count
    stays where the curve put it; rigid parts: exactly 8."""
    model, _, scans = hybrid_truth(M=8, seed=seed)
    _, info = articulated_parts(*centred(scans[0], scans), model.faces, k_max=14)
    assert info["splits"] == [] and 8 <= info["parts"] <= 11
    scans, faces, _, rest, _, _ = rigid_scans(8, seed=seed)
    _, info = articulated_parts(*centred(rest, scans), faces, k_max=14)
    assert info["parts"] == 8
