"""Vertices split at seams (solver.learn.seams): found exactly, welded for learning, and the learned
rig given back for every copy, the same rig as from the unsplit mesh."""
import numpy as np

from articula.solver.learn.pipeline import learn_rig
from articula.solver.learn.seams import Seams

from articula.sample_scenes.tube_scans import hybrid_truth


def _split_at_seam(scans, faces):
    """The mesh with every vertex that the faces right of x = 0 share with the others copied (a seam
    along the cut, as a UV seam splits it): ``(scans (M,V',3), faces, source (V',) input vertex of each)``."""
    right = scans[0][faces].mean(axis=1)[:, 0] > 0
    shared = np.intersect1d(faces[right], faces[~right])
    V = scans.shape[1]
    copy_of = np.full(V, -1)
    copy_of[shared] = V + np.arange(len(shared))
    f = faces.copy()
    f[right] = np.where(copy_of[faces[right]] >= 0, copy_of[faces[right]], faces[right])
    source = np.r_[np.arange(V), shared]
    return scans[:, source], f, source


def test_seam_copies_found_and_welded():
    model, _, scans = hybrid_truth(M=4, seed=0)
    split, faces, source = _split_at_seam(scans, model.faces)
    seams = Seams.of(split)
    assert seams.welded == len(source) - scans.shape[1] > 10
    assert np.array_equal(seams.index, seams.index[:scans.shape[1]][source])   # a copy welds to its original
    welded, wfaces = seams.weld(split, faces)
    assert welded.shape[1] == scans.shape[1]
    assert np.allclose(welded[:, seams.index], split)
    assert Seams.of(scans) is None                                      # nothing coincides in the tube itself
    moved = split.copy()
    moved[2, -1] += 1e-3                                                # a copy apart in one scan: not a seam
    assert Seams.of(moved).welded == seams.welded - 1


def test_learning_a_split_mesh_equals_the_unsplit_one():
    """Without welding the seam cuts the tube into two halves (refused as two bodies); with it the rig is
    the one learned from the unsplit mesh, every copy carrying its vertex's rest position and weights."""
    model, _, scans = hybrid_truth(M=6, seed=1)
    split, faces, source = _split_at_seam(scans, model.faces)
    options = dict(parts=8, max_iterations=0, symmetry=False)
    whole = learn_rig(scans, model.faces, **options)
    got = learn_rig(split, faces, **options)
    assert got.report["welded_vertices"] == len(source) - scans.shape[1]
    assert np.array_equal(got.model.faces, faces)
    assert np.allclose(got.model.rest_vertices, whole.model.rest_vertices[source])
    assert np.array_equal(got.model.anchor, whole.model.anchor[source])
    assert np.allclose(got.model.skeleton.heads, whole.model.skeleton.heads)
    assert got.scan_distances.shape == split.shape[:2]
