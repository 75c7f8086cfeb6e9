"""Mirror pairs of parts from the vertex mirror map (solver.skeleton_init.map_pair_votes)."""
import numpy as np

from articula.solver.skeleton_init import build_skeleton, map_pair_votes

from .learn_data import PARTS, body, rigid_scans


def test_map_pair_votes_pairs_the_mirrored_limbs_left_first():
    rest, faces, labels = body()
    votes = map_pair_votes(rest, rest[None], labels, faces, len(PARTS))
    left = {PARTS.index(n): PARTS.index(n[:-1] + "R") for n in PARTS if n.endswith(".L")}
    assert set(votes) == set(left.items())                      # .L parts are at +x: the plane normal's side


def test_map_pair_votes_none_without_symmetry():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(200, 3)) * [1.0, 2.0, 3.0] + rng.normal(scale=0.3, size=(200, 3))
    tri = np.array([[k, k + 1, k + 2] for k in range(198)])
    assert map_pair_votes(pts, pts[None], np.zeros(200, dtype=np.int64), tri, 1) is None


def test_build_skeleton_names_mirror_pairs_from_the_map():
    scans, faces, labels, rest, _, _ = rigid_scans(6, seed=2)
    skeleton, order, bone_of_part, pairs = build_skeleton(rest, labels, faces, len(PARTS), symmetry_scans=scans)
    found = {(int(order[l]), int(order[r])) for l, r in pairs}
    assert found == {(2, 4), (3, 5), (6, 7)}
