"""The skeleton-tree helpers both trackers' limb searches share (solver.tracking.limbs): the direction
lattice (closed-form checks), bone depths and subtrees against brute force over ancestors."""
import numpy as np

from articula.solver.tracking.limbs import bone_depths, sphere_directions, subtrees

PARENTS = [-1, 0, 1, 2, 0, 4, 5, 0, 7]


def _ancestors(parents, b):
    out = []
    while b >= 0:
        out.append(b)
        b = parents[b]
    return out


def test_sphere_directions_are_unit_and_spread():
    d = sphere_directions(64)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert np.linalg.norm(d.mean(axis=0)) < 0.02
    cos = d @ d.T - 2.0 * np.eye(64)
    nearest = np.degrees(np.arccos(cos.max(axis=1)))
    assert 15.0 < nearest.min() and nearest.max() < 35.0          # every direction has a neighbour ~25 deg away
    rng = np.random.default_rng(0)
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    assert np.degrees(np.arccos((u @ d.T).max(axis=1))).max() < 25.0     # no direction far from the lattice


def test_subtrees_match_brute_force():
    trees = subtrees(PARENTS)
    for b in range(len(PARENTS)):
        assert sorted(trees[b]) == [c for c in range(len(PARENTS)) if b in _ancestors(PARENTS, c)]
        assert trees[b][0] == b


def test_bone_depths_count_ancestors():
    assert bone_depths([-1, 0, 1, 0, 3, -1]).tolist() == [0, 1, 2, 1, 2, 0]
    assert bone_depths(PARENTS).tolist() == [len(_ancestors(PARENTS, b)) - 1 for b in range(len(PARENTS))]
