"""Twist-weight candidates (weights.candidates): bounds, the anchor rule, move directions."""
import numpy as np

from articula.solver.learn.weights.candidates import candidates, children_table

from articula.sample_scenes.tube_scans import hybrid_truth


def test_candidates_respect_bounds_and_anchor_rule():
    model, _, _ = hybrid_truth(2)
    sk = model.skeleton
    child = sk.child_matrix()
    model.twist_weights[np.flatnonzero(model.twist_weights[:, 3] > 0)[:3], 3] = 1.0   # "forward" applies
    n_back = n_fwd = 0
    for anchor, tw, valid, _ in candidates(model.anchor, model.twist_weights.astype(np.float64), sk.parents):
        t = tw[valid]
        assert np.all(t >= 0) and np.all(t <= 1) and np.all(t.sum(1) <= 1 + 1e-9)
        assert not np.any((t != 0) & ~child[anchor[valid]])
        n_back += np.sum(valid & (anchor == sk.parents[model.anchor]))
        n_fwd += np.sum(valid & (sk.parents[anchor] == model.anchor))
    assert n_back > 0 and n_fwd > 0                          # both re-expressions occur on this body


def test_directions_name_moves_independently_of_the_step():
    """A candidate slot's direction is the same at every step δ and distinct between moves: the slots
    of steps (0.2,) and (0.05,) pair up one to one, and stepless slots (stay, re-expressions) are −1."""
    model, _, _ = hybrid_truth(2)
    sk = model.skeleton
    model.twist_weights[np.flatnonzero(model.twist_weights[:, 3] > 0)[:3], 3] = 1.0   # "forward" applies
    tw64 = model.twist_weights.astype(np.float64)
    big = [way for *_, way in candidates(model.anchor, tw64, sk.parents, (0.2,))]
    small = [way for *_, way in candidates(model.anchor, tw64, sk.parents, (0.05,))]
    assert big == small
    stepped = [w for w in big if w >= 0]
    assert len(stepped) == len(set(stepped)) and big.count(-1) == 3      # stay, backward at 1, forward at 0


def test_children_table_lists_each_bone_s_children():
    """children_table against the parent array read directly: row b holds the bones whose parent is b,
    ascending, padded with -1; at least one column when no bone has children."""
    parents = np.array([-1, 0, 0, 1, 0, 3, -1])
    table = children_table(parents)
    assert table.shape == (7, 3)
    for b in range(7):
        kids = [c for c in range(7) if parents[c] == b]
        assert table[b].tolist() == kids + [-1] * (3 - len(kids))
    assert children_table(np.array([-1])).tolist() == [[-1]]
