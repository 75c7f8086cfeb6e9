"""Mirror symmetry: the vertex mirror map (solver.learn.mirror_map), mirror-image parts cut alike
(segment(mirror=...)), symmetry planes and the left/right part and bone pairs (solver.learn.symmetry)."""
from types import SimpleNamespace

import numpy as np
import pytest

from articula.solver.geometry.procrustes import fit_parts
from articula.solver.learn.mirror_map import mirror_map, polygons_of
from articula.solver.learn.segmentation import segment
from articula.solver.learn.skeleton import build_skeleton
from articula.solver.learn.symmetry import (MAP_COVERAGE, consistent_pairs, continuing_pairs, map_pair_votes,
                                            mirror_pairs, mirror_partners, mirrored_labels, symmetry_planes,
                                            unequal_pairs)

from articula.sample_scenes.tube_scans import body, hybrid_truth, rigid_scans, rotvec_matrix


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


def test_mirrored_labels_match_brute_force():
    """Every mapped vertex goes to the part c of the compatible pair (c, d) with the least
    err[v, c] + err[m(v), d]; unmapped vertices to their best part."""
    rng = np.random.default_rng(0)
    V, k = 60, 5
    err = rng.uniform(size=(V, k))
    perm = rng.permutation(V)
    mirror = np.full(V, -1)
    mirror[perm[:20]], mirror[perm[20:40]] = perm[20:40], perm[:20]         # an involution on 40 vertices
    compatible = rng.uniform(size=(k, k)) < 0.5
    compatible = compatible | compatible.T | np.eye(k, dtype=bool)
    got = mirrored_labels(err, mirror, compatible)
    for v in range(V):
        if mirror[v] < 0:
            assert got[v] == np.argmin(err[v])
        else:
            cost = [min(err[v, c] + err[mirror[v], d] for d in range(k) if compatible[c, d]) for c in range(k)]
            assert got[v] == np.argmin(cost)


def _rigid_body(M=10, seed=0):
    """The tube body, rigidly posed: rest, scans, faces, its true parts and their per-scan rigid maps."""
    scans, faces, labels, rest, _, _ = rigid_scans(M, seed)
    R, t = fit_parts(rest, scans, labels, 8)
    return rest, scans, faces, labels, R, t


def test_symmetry_plane_of_a_tilted_mirror_body():
    rest, _, _, labels, _, _ = _rigid_body(M=3)
    Rt = rotvec_matrix(np.array([0.1, 0.2, 0.3]))
    moved = rest @ Rt.T + [0.3, -0.2, 0.1]
    n_true = Rt @ [1.0, 0, 0]
    planes = symmetry_planes(moved)
    assert any(abs(n @ n_true) > 1 - 1e-9 for n, _, _ in planes)
    n, off, _ = next(p for p in planes if abs(p[0] @ n_true) > 0.5)
    assert abs(off - n @ [0.3, -0.2, 0.1]) < 1e-9
    assert len(mirror_pairs(moved, labels, 8, (n, off, 0.0))) == 3


def test_consistent_pairs_keeps_only_structural_mirror_pairs():
    #        0 root; 1, 2 thighs (siblings); 3 under 1, 4 under 2 (shins); 5 neck under 0 (small); 6 arm
    parent = np.array([-1, 0, 0, 1, 2, 0, 0])
    sizes = np.array([900, 300, 310, 200, 190, 60, 280])
    votes = {(5, 6): 3,            # neck vs arm: siblings but sizes 60 vs 280 -> rejected
             (1, 2): 1,            # thighs
             (4, 3): 2,            # shins, voted right-before-left: left follows the parents' pair
             (0, 5): 1,            # root never pairs
             (3, 6): 1}            # parents 1 and 0 are not a pair -> rejected
    assert consistent_pairs(votes, parent, sizes) == [(1, 2), (3, 4)]


def test_consistent_pairs_rejects_parts_cut_differently():
    """Mirror parts whose vertex counts differ by more than MIRROR_SIZE_RATIO were cut at different places
    (MakeHuman at 19 parts: a left shin part with the heel, 371 vertices, vs the right shin alone, 240)."""
    parent = np.array([-1, 0, 0, 1, 2])
    assert consistent_pairs({(1, 2): 2, (3, 4): 2}, parent, np.array([900, 342, 342, 371, 240])) == [(1, 2)]
    assert consistent_pairs({(1, 2): 2, (3, 4): 2}, parent, np.array([900, 342, 342, 371, 340])) == [(1, 2), (3, 4)]


def _limbs():
    """0 root; 1 / 2 mirrored upper limbs continuing into 3 / 4 (end bones): heads, tails, parents."""
    parents = np.array([-1, 0, 0, 1, 2])
    heads = np.array([[0, 0, 1.0], [0.1, 0, 1], [-0.1, 0, 1], [0.1, 0, 0.6], [-0.1, 0, 0.62]])
    tails = np.array([[0, 0, 1.5], heads[3], heads[4], [0.1, 0, 0.2], [-0.1, 0, 0.2]])
    return heads, tails, parents


def test_unequal_pairs_flags_mirror_bones_of_different_length():
    heads, tails, parents = _limbs()
    assert unequal_pairs(heads, tails, parents, [(1, 2), (3, 4)]) == []          # 0.40 vs 0.38 m: within 10 %
    heads[4, 2] = tails[2, 2] = 0.7                                              # 0.40 vs 0.30 m
    assert unequal_pairs(heads, tails, parents, [(1, 2), (3, 4)]) == [(1, 2)]    # end bones are not compared


def test_continuing_pairs_are_the_pairs_whose_bones_both_reach_a_child():
    heads, tails, parents = _limbs()
    skeleton = SimpleNamespace(heads=heads, tails=tails, parents=parents)
    assert continuing_pairs(skeleton, [(1, 2), (3, 4)]) == [(1, 3, 2, 4)]
    tails = tails.copy()
    tails[2] += [0.0, 0.0, 0.01]                                                 # 2 ends short of 4's head
    assert continuing_pairs(SimpleNamespace(heads=heads, tails=tails, parents=parents), [(1, 2)]) == []


def test_mirror_pairs_from_the_vertex_mirror_map():
    """With the mesh's vertex mirror map the pairs come from it: the same pairs and names as from the
    symmetry planes on the symmetric rest mesh, and the same parts paired from every posed scan, where no
    plane reflects the whole body."""
    rest, scans, faces, labels, R, t = _rigid_body()
    planes, order, _, plane_pairs = build_skeleton(rest, labels, faces, 8, R, t)
    assert len(plane_pairs) == 3
    mirror = mirror_map(rest, scans, faces)
    assert mirror is not None and np.mean(mirror >= 0) >= MAP_COVERAGE
    sk, _, _, pairs = build_skeleton(rest, labels, faces, 8, R, t, mirror=mirror)
    assert pairs == plane_pairs and sk.names == planes.names
    expected = {frozenset((int(order[l]), int(order[r]))) for l, r in plane_pairs}
    for m in range(len(scans)):                # (a scan's own rigid turn may flip which side is +X)
        assert {frozenset(p) for p in map_pair_votes(scans[m], labels, 8, mirror)} == expected, m
    broken = np.where(np.arange(len(mirror)) % 2 == 0, mirror, -1)      # half the map: planes instead
    assert build_skeleton(rest, labels, faces, 8, R, t, mirror=broken)[3] == plane_pairs
