"""Removing leaf bones that hold no vertex (solver.learn.prune): found exactly, and the posed surface of
every scan unchanged."""
import numpy as np

from articula.solver.geometry.rotations import rotvec_to_quat
from articula.solver.learn.prune import drop_bones, empty_leaves, remap_pairs
from articula.solver.rig.model import Model, Poses, Skeleton
from articula.solver.rig.skinning import hybrid_skin

from articula.sample_scenes.tube_scans import hybrid_truth


def _with_empty_bones(model, poses, parents, weight_on=None):
    """``model``/``poses`` with extra bones (``parents`` of each; no vertex; a 0.5 weight on the extra bone
    ``weight_on`` for the vertices anchored at its parent) posed at random."""
    sk, extra = model.skeleton, len(parents)
    heads, tails = list(sk.heads), list(sk.tails)
    for p in parents:                                   # each new bone starts at its parent's tail
        heads.append(tails[p])
        tails.append(tails[p] + [0.0, 0.05, 0.0])
    frames = np.vstack([sk.frames, np.broadcast_to(np.eye(3), (extra, 3, 3))])
    skeleton = Skeleton(sk.names + [f"extra_{i}" for i in range(extra)], np.r_[sk.parents, parents],
                        np.array(heads), np.array(tails), frames)
    V = model.num_vertices
    twist = np.hstack([model.twist_weights, np.zeros((V, extra), np.float32)])
    swing = np.hstack([model.swing_weights, np.zeros((V, extra), np.float32)])
    if weight_on is not None:
        b = sk.num_bones + weight_on
        mine = model.anchor == skeleton.parents[b]
        swing[mine] *= 0.5
        swing[mine, b] = 0.5
    rot = np.random.default_rng(5).normal(scale=0.4, size=(len(poses.rotations), extra, 3))
    posed = Poses(np.concatenate([poses.rotations, rotvec_to_quat(rot)], axis=1), poses.translations, poses.scales)
    return Model(model.rest_vertices, model.faces, skeleton, model.anchor, twist, swing), posed


def test_empty_leaves_found_and_dropped_without_changing_the_surface():
    model, poses, _ = hybrid_truth(M=5, seed=0)
    B = model.skeleton.num_bones
    leaf = next(b for b in range(B) if not model.skeleton.children(b))
    # a chain of two empty bones below a leaf, and one empty bone below bone 1
    big, big_poses = _with_empty_bones(model, poses, [leaf, B, 1])
    assert list(empty_leaves(big)) == [B, B + 1, B + 2]
    small, small_poses, new_index = drop_bones(big, big_poses, empty_leaves(big))
    small.validate()
    assert small.skeleton.names == model.skeleton.names and list(new_index[B:]) == [-1, -1, -1]
    assert np.allclose(hybrid_skin(small, small_poses), hybrid_skin(big, big_poses), atol=1e-12)
    assert np.allclose(hybrid_skin(small, small_poses), hybrid_skin(model, poses), atol=1e-12)


def test_a_bone_with_weights_is_kept():
    model, poses, _ = hybrid_truth(M=3, seed=1)
    B = model.skeleton.num_bones
    big, _ = _with_empty_bones(model, poses, [1, 2], weight_on=0)
    assert list(empty_leaves(big)) == [B + 1]


def test_pairs_renumbered_and_dropped():
    new_index = np.array([0, -1, 1, 2, -1, 3])
    assert remap_pairs([(2, 3, 5, 0), (1, 2, 3, 5), (3, 5)], new_index) == [(1, 2, 3, 0), (2, 3)]
