"""Mirror-symmetric segmentation (solver.learn.segmentation: mirror_map, mirror_partners, segment(mirror=...))."""
import numpy as np
import pytest

from articula.solver.learn.segmentation import mirror_map, mirror_partners, polygons_of, segment

from ..learn_data import body, hybrid_truth


def _exact_mirror(points):
    """Index of each point's image under x -> -x (the points are exactly symmetric)."""
    refl = points * np.array([-1.0, 1.0, 1.0])
    return np.argmin(np.linalg.norm(points[None] - refl[:, None], axis=2), axis=1)


def _asymmetric_cuts(labels, mirror, k):
    """Vertices of mirror-paired parts whose mirror vertex is not in the partner part (fixed points of the
    map are left out: a vertex on the plane cannot be in both of two paired parts)."""
    partner = mirror_partners(labels, mirror, k)
    v = np.flatnonzero((partner[labels] >= 0) & (mirror != np.arange(len(labels))))
    return int(np.sum(labels[mirror[v]] != partner[labels[v]]))


def _quad_strip(n=10, h=6):
    """A flat quad grid x = sign(i)|i|^1.2 (i = -n..n: mirrored columns alike, other columns not),
    y = j² (j = 0..h: no mirror plane across y), each quad split
    (a, b, c), (a, c, d) — so mirror-image quads are split along different diagonals — with the part
    x > 0.7 n bent out of the plane.
    Returns ``(flat (V,3), bent (V,3), faces (F,3))``."""
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(h + 1), indexing="ij")
    x = np.sign(i) * np.abs(i) ** 1.2
    flat = np.stack([x.ravel(), j.ravel() ** 2.0, np.zeros(i.size)], axis=1)
    idx = np.arange(i.size).reshape(i.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.stack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)], axis=1).reshape(-1, 3)
    bent = flat.copy()
    x = np.maximum(flat[:, 0] - 0.7 * n ** 1.2, 0.0)
    bent[:, 2] = 0.5 * x ** 2
    return flat, bent, faces


def test_mirror_map_follows_the_quad_topology_where_the_shape_is_not_symmetric():
    flat, bent, faces = _quad_strip()
    assert len(polygons_of(faces, bent)) == len(faces) // 2                 # the quads are found again
    m = mirror_map(bent, bent[None], faces)
    assert m is not None and np.array_equal(m, _exact_mirror(flat))        # also in the bent part


def test_mirror_map_geometric_fallback_and_none_without_symmetry():
    rest, faces, _ = body()                                                # non-manifold joins: no topology
    m = mirror_map(rest, rest[None], faces)
    assert m is not None and np.array_equal(m, _exact_mirror(rest))
    rng = np.random.default_rng(0)
    blob = rng.normal(size=(200, 3)) * [1.0, 2.0, 3.0] + rng.normal(scale=0.3, size=(200, 3))
    tri = np.array([[k, k + 1, k + 2] for k in range(198)])
    assert mirror_map(blob, blob[None], tri) is None


@pytest.mark.parametrize("seed", [1, 4, 5])
def test_mirror_parts_are_cut_alike(seed):
    """Smoothly skinned tube body, left and right limbs posed differently: the plain segmentation cuts
    some mirrored joints at different places; with the mirror map both sides are cut alike, every part
    stays connected and the fit error hardly changes."""
    model, poses, scans = hybrid_truth(M=8, seed=seed)
    rest, faces, _ = body()
    exact = _exact_mirror(rest)
    plain, rms_plain = segment(scans[0], scans, faces, 8, mirror=False)
    sym, rms_sym = segment(scans[0], scans, faces, 8)
    assert _asymmetric_cuts(plain, exact, 8) > 0                            # the data discriminates
    assert _asymmetric_cuts(sym, exact, 8) == 0
    assert rms_sym <= 1.02 * rms_plain
    from scipy.sparse.csgraph import connected_components
    from articula.solver.geometry.mesh_graph import adjacency
    A = adjacency(faces, len(rest))
    for c in range(8):
        idx = np.flatnonzero(sym == c)
        assert connected_components(A[idx][:, idx], directed=False)[0] == 1
    again, _ = segment(scans[0], scans, faces, 8, mirror=exact)             # a given map: same result
    assert np.array_equal(again, sym)
