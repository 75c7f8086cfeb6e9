"""G2 (segmentation by motion), G5 (Procrustes) and G7 (uniform Laplacian) on synthetic data."""
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components

from articula.solver.errors import ArticulaInputError
from articula.solver.laplacian import adjacency, components, uniform_laplacian
from articula.solver.procrustes import fit_parts, fit_rigid
from articula.solver.segmentation import choose_num_parts, knee, make_parts_connected, segment

from .learn_data import body, rigid_scans, rotvec_matrix


def _accuracy(truth, found):
    C = np.zeros((truth.max() + 1, found.max() + 1))
    np.add.at(C, (truth, found), 1)
    r, c = linear_sum_assignment(-C)
    return C[r, c].sum() / len(truth)


def _is_connected(labels, faces):
    """Every part is one connected piece (checked on the induced sub-graph of each part)."""
    A = adjacency(faces, len(labels))
    for c in np.unique(labels):
        idx = np.flatnonzero(labels == c)
        if connected_components(A[idx][:, idx], directed=False)[0] != 1:
            return False
    return True


# ---------------------------------------------------------------- G5 Procrustes

def test_procrustes_recovers_rigid_transform_exactly():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(4, 30, 3))
    R = rotvec_matrix(rng.normal(size=(4, 3)))
    t = rng.normal(size=(4, 3))
    dst = np.einsum("bij,bpj->bpi", R, src) + t[:, None]
    R_fit, t_fit = fit_rigid(src, dst)
    assert np.abs(R_fit - R).max() < 1e-10 and np.abs(t_fit - t).max() < 1e-10
    assert np.allclose(np.linalg.det(R_fit), 1.0)


def test_procrustes_never_returns_a_reflection():
    rng = np.random.default_rng(2)
    src = rng.normal(size=(20, 3))
    dst = src * np.array([-1.0, 1.0, 1.0])          # a mirror image: best proper rotation, not the mirror
    R, _ = fit_rigid(src, dst)
    assert np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_fit_parts_matches_per_part_fit():
    scans, faces, labels, rest, Rm, tm = rigid_scans(5, seed=3)
    R, t = fit_parts(rest, scans, labels, 8)
    assert np.abs(R - Rm).max() < 1e-9 and np.abs(t - tm).max() < 1e-9
    R2, t2 = fit_rigid(rest[labels == 3], scans[2][labels == 3])
    assert np.allclose(R2, R[2, 3], atol=1e-12) and np.allclose(t2, t[2, 3], atol=1e-12)


# ---------------------------------------------------------------- G7 Laplacian

def test_uniform_laplacian_properties():
    n = 6
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    L = uniform_laplacian(faces, n * n)
    interior = idx[1:-1, 1:-1].ravel()
    assert np.abs(L @ verts)[interior].max() < 1e-12                  # flat regular grid: 0 inside
    assert np.abs(L @ verts).max() > 0.1                              # but not on the border
    assert np.allclose(L @ np.ones(n * n), 0)                          # constants are in the kernel
    rng = np.random.default_rng(0)
    p, q = rng.normal(size=(2, n * n, 3))
    assert np.allclose(L @ (2 * p - 3 * q), 2 * (L @ p) - 3 * (L @ q))  # linear
    # by definition: v - mean of one-ring, brute force on a vertex
    A = adjacency(faces, n * n).toarray()
    v = 7
    assert np.allclose((L @ p)[v], p[v] - p[A[v] > 0].mean(axis=0))


# ---------------------------------------------------------------- G2 segmentation

def test_segmentation_recovers_parts_and_is_connected():
    scans, faces, labels, rest, _, _ = rigid_scans(10, seed=0)
    found, rms = segment(rest, scans, faces, 8, seed=0)
    assert len(np.unique(found)) == 8
    assert _accuracy(labels, found) > 0.98
    assert _is_connected(found, faces)
    assert rms < 1e-6


def test_segmentation_deterministic_under_seed():
    scans, faces, _, rest, _, _ = rigid_scans(6, seed=4)
    a, _ = segment(rest, scans, faces, 8, seed=5)
    b, _ = segment(rest, scans, faces, 8, seed=5)
    assert np.array_equal(a, b)


def test_islands_are_merged_into_a_neighbour():
    verts, faces, labels = body()
    n, _ = components(faces, len(verts))
    assert n == 1
    bad = labels.copy()
    island = np.flatnonzero(labels == 1)[:8]          # one ring of the head given to a leg part
    bad[island] = 6
    err = np.ones((len(verts), 8))
    err[:, 1] = 0.0                                    # the head part fits it best
    fixed = make_parts_connected(bad, adjacency(faces, len(verts)), err)
    assert _is_connected(fixed, faces)
    assert np.array_equal(fixed, labels)


def test_number_of_parts_chosen_from_motion():
    scans, faces, _, rest, _, _ = rigid_scans(8, seed=1)
    k, errors = choose_num_parts(rest, scans, faces, k_max=11)
    assert k == 8
    assert errors[7] < 1e-6 < errors[6]


def test_knee_of_curves():
    assert knee([10, 5, 1, 0.9, 0.8, 0.7]) == 2
    assert knee([1, 1, 1]) == 0


def test_too_many_parts_for_vertices():
    scans, faces, _, rest, _, _ = rigid_scans(4)
    with pytest.raises(ArticulaInputError):
        segment(rest, scans, faces, len(rest) + 1)
