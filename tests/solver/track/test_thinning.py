"""Thinning of dense captures (:func:`solver.track.captures.thin_mesh`): captured vertices kept, valid
triangles, and a cell size as fine as the point budget allows (checked against a dense scan of sizes)."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from articula.sample_scenes import synthetic
from articula.solver.depth.frames import voxel_groups
from articula.solver.track import captures as cp
from articula.solver.track.metrics import point_to_mesh


@pytest.fixture(scope="module")
def body():
    return synthetic.tube_body()


def test_thin_mesh_keeps_the_surface_and_valid_triangles(body):
    v, f = body.rest_vertices, body.faces
    thin, tris = cp.thin_mesh(v, f, len(v) // 4)
    assert len(thin) <= len(v) // 4
    assert tris.min() >= 0 and tris.max() < len(thin)
    assert (np.sort(tris, axis=1)[:, :-1] != np.sort(tris, axis=1)[:, 1:]).all()
    # every kept vertex is an original one; every original vertex lies near the thinned mesh
    assert cKDTree(v).query(thin)[0].max() == 0.0
    assert np.median(point_to_mesh(v, thin, tris)) < 0.01


@pytest.mark.parametrize("share", [0.05, 0.2, 0.5, 0.9])
def test_cell_size_is_about_the_finest_within_the_budget(body, share):
    """The search's size keeps the count within the budget, and no size 5 % finer (from a scan of 400
    sizes over the extent) does: the count falls with the size up to grid alignment, so the size found
    is within a few per cent of the finest one that fits."""
    v = body.rest_vertices - body.rest_vertices.min(axis=0)
    budget = int(share * len(v))
    size = cp._cell_size(v, body.faces, budget)
    assert voxel_groups(v, size)[1] <= budget
    scan = np.geomspace(1e-4, float(np.ptp(v, axis=0).max()), 400)
    counts = np.array([voxel_groups(v, s)[1] for s in scan])
    finest = scan[np.argmax(counts <= budget)]                 # the first (finest) size within the budget
    assert size <= 1.05 * finest
    assert len(cp.thin_mesh(body.rest_vertices, body.faces, budget)[0]) >= 0.8 * budget


def test_cell_size_of_a_cloud_without_triangles_still_fits():
    """No triangles (no area to start from): the search starts from the extent and still fits."""
    pts = np.random.default_rng(0).uniform(0, 1, (5000, 3))
    size = cp._cell_size(pts, np.zeros((0, 3), np.int64), 700)
    assert 0.9 * 700 <= voxel_groups(pts, size)[1] <= 700
