"""Two-ring colouring and halves (weights.colouring), checked by brute force over the two-ring pattern."""
import numpy as np

from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.learn.weights.colouring import TwoRing, subset_classes, two_ring_colouring

from articula.sample_scenes.tube_scans import body, hybrid_truth


def test_two_ring_colouring_separates_interacting_vertices():
    _, faces, _ = body()
    V = faces.max() + 1
    L = uniform_laplacian(faces, V)
    A1 = (L != 0).astype(float)
    ring2 = (A1 @ A1).tocsr()
    colour = two_ring_colouring(ring2)
    rows, cols = ring2.nonzero()
    off = rows != cols
    assert np.all(colour[rows[off]] != colour[cols[off]])
    assert colour.max() + 1 <= ring2.getnnz(axis=1).max()        # greedy bound: at most max degree + 1


def test_halves_are_more_than_two_rings_apart_and_balance_the_work():
    """TwoRing.halves: half_a, half_b and the band partition the vertices, no vertex of half_b lies in the
    two-ring of half_a (brute force over the ring2 pattern), and the halves' work differs by at most the
    work of the heaviest levels (the cut moves one level at a time)."""
    model, _, _ = hybrid_truth(2)
    graph = TwoRing(uniform_laplacian(model.faces, model.num_vertices))
    work = np.random.default_rng(1).uniform(1.0, 9.0, model.num_vertices)
    half_a, half_b, band = graph.halves(work)
    V = model.num_vertices
    assert len(half_a) and len(half_b) and band.sum() < 0.25 * V
    assert np.array_equal(np.sort(np.concatenate([half_a, half_b, np.flatnonzero(band)])), np.arange(V))
    assert not np.isin(graph.ring2[half_a].indices, half_b).any()
    per_level = np.bincount(graph.levels, weights=work)
    assert abs(work[half_a].sum() - work[half_b].sum()) <= 3 * per_level.max()


def test_band_classes_are_two_ring_independent_and_cover_the_band():
    """subset_classes: every masked vertex in exactly one class, no two vertices of a class within two
    rings (brute force over the ring2 pattern)."""
    model, _, _ = hybrid_truth(2)
    graph = TwoRing(uniform_laplacian(model.faces, model.num_vertices))
    _, _, band = graph.halves(np.ones(model.num_vertices))
    classes = subset_classes(graph.ring2, band)
    assert np.array_equal(np.sort(np.concatenate(classes)), np.flatnonzero(band))
    for idx in classes:
        block = graph.ring2[idx][:, idx].tocoo()
        assert np.all(block.row == block.col)                      # only each vertex with itself
    assert len(classes) <= len([c for c in graph.classes if band[c].any()])
    assert subset_classes(graph.ring2, np.zeros(model.num_vertices, bool)) == []
