"""G2 (segmentation by motion), G5 (Procrustes) and G7 (uniform Laplacian) on synthetic data."""
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components

from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.mesh_graph import adjacency, components, uniform_laplacian
from articula.solver.geometry.procrustes import fit_parts, fit_rigid
from articula.solver.learn.segmentation import (Clustering, Mesh, Sample, centred, choose_num_parts, grid_sample,
                                          make_parts_connected, parts_from_curve, segment, sums_cost)

from articula.sample_scenes.tube_scans import body, hybrid_truth, rigid_scans, rotvec_matrix


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
    scans, faces, labels, rest, _, _ = rigid_scans(5, seed=2)
    n, _ = components(faces, len(rest))
    assert n == 1
    bad = labels.copy()
    island = np.flatnonzero(labels == 1)[:8]          # one ring of the head given to a leg part
    bad[island] = 6
    fixed = make_parts_connected(Mesh(*centred(rest, scans)), bad, adjacency(faces, len(rest)))
    assert _is_connected(fixed, faces)
    assert np.array_equal(fixed, labels)              # back to the head, whose motion fits it exactly


def test_large_island_becomes_a_part_of_its_own():
    """A part made of two distant pieces with one motion (forearm.R moved like forearm.L and labelled
    so) keeps k parts by taking the island as a part and merging two adjacent parts that move alike
    (thigh.L moved with the torso) instead of gluing it to a neighbour it does not fit."""
    scans, faces, labels, rest, Rm, tm = rigid_scans(6, seed=3)
    for part, like in ((6, 0), (5, 3)):
        scans[:, labels == part] = np.einsum("mij,vj->mvi", Rm[:, like], rest[labels == part]) + tm[:, like, None]
    bad = labels.copy()
    bad[labels == 5] = 3                               # the island
    bad[labels == 7] = 5                               # labels 0..6, all used
    fixed = make_parts_connected(Mesh(*centred(rest, scans)), bad, adjacency(faces, len(rest)))
    assert _is_connected(fixed, faces)
    assert len(np.unique(fixed)) == 7
    forearm_r = np.unique(fixed[labels == 5])
    assert len(forearm_r) == 1 and forearm_r[0] not in fixed[labels != 5]
    assert len(np.unique(fixed[(labels == 0) | (labels == 6)])) == 1


def test_number_of_parts_chosen_from_motion():
    scans, faces, _, rest, _, _ = rigid_scans(8, seed=1)
    k, errors = choose_num_parts(rest, scans, faces, k_max=11)
    assert k == 8
    assert errors[7] < 1e-6 < errors[6]


def test_number_of_parts_from_curves():
    assert parts_from_curve([10, 5, 1, 0.5, 0, 0], floor=1e-9) == 4                  # exact: E = 0
    assert parts_from_curve([100, 50, 20, 10, 5, 2.9, 2, 1.5]) == 5                # E <= 3 % of E(1)
    assert parts_from_curve([100, 60, 50, 49, 48.5, 48.4]) == 2                    # plateau (noise)
    assert parts_from_curve([1, 1, 1]) == 0


def test_soft_body_parts_and_curve():
    """Hybrid-skinned tube (8 bones, smooth joints): the curve falls steeply to 8 parts; the rule may
    add a part or two for the skin bending; segment() reproduces the curve at full resolution."""
    model, _, scans = hybrid_truth(M=8, seed=0)
    k, errors = choose_num_parts(scans[0], scans, model.faces, k_max=12)
    assert 8 <= k <= 10
    assert np.all(np.diff(errors) <= 1e-12)
    assert errors[7] < 0.5 * errors[6]
    labels, rms = segment(scans[0], scans, model.faces, 8)
    assert _is_connected(labels, model.faces) and len(np.unique(labels)) == 8
    assert abs(rms - errors[7]) < 0.2 * errors[7]


def test_cell_subsample_weights_and_spread():
    rest, _, _ = body()
    idx, cell = grid_sample(rest, 200)
    assert 190 <= len(idx) <= 210 and len(np.unique(idx)) == len(idx)
    assert np.array_equal(cell[idx], np.arange(len(idx)))                # every sample is in its own cell
    assert np.bincount(cell).sum() == len(rest) and np.bincount(cell).min() >= 1
    idx, cell = grid_sample(rest, 10 * len(rest))
    assert np.array_equal(idx, np.arange(len(rest)))


def test_incremental_clustering_matches_fresh_fit():
    """Relabelling updates sums, fits and errors exactly as a fit from scratch; the expanded errors and the
    cost from sums equal the direct residuals."""
    scans, faces, labels, rest, _, _ = rigid_scans(5, seed=6)
    scans = scans + np.random.default_rng(0).normal(scale=0.01, size=scans.shape)
    rest, scans = centred(rest, scans)
    sample = Sample.of_mesh(rest, scans, 150)
    rng = np.random.default_rng(1)
    cl = Clustering(sample, rng.integers(8, size=len(sample)), 8)
    new = cl.labels.copy()
    new[:40] = rng.integers(8, size=40)
    cl.relabel(new)
    fresh = Clustering(sample, new, 8)
    assert np.allclose(cl.R, fresh.R, atol=1e-9) and np.allclose(cl.err, fresh.err, atol=1e-9)
    mesh = Clustering(Mesh(rest, scans), labels, 8)
    R, t = fit_parts(rest, scans, labels, 8)
    direct = np.sum((np.einsum("mvij,vj->mvi", R[:, labels], rest) + t[:, labels] - scans) ** 2, axis=(0, 2))
    assert np.allclose(mesh.R, R, atol=1e-9)
    assert np.allclose(mesh.err[np.arange(len(rest)), labels], direct, atol=1e-9)
    S, n = Mesh(rest, scans).sums(np.arange(len(rest)), labels, 8)
    assert np.allclose(sums_cost(S, n, len(scans)), np.bincount(labels, weights=direct), atol=1e-9)


def test_too_many_parts_for_vertices():
    scans, faces, _, rest, _, _ = rigid_scans(4)
    with pytest.raises(ArticulaInputError):
        segment(rest, scans, faces, len(rest) + 1)
