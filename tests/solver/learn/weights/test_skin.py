"""Candidate skinning (weights.skin) against hybrid_skin, the reference."""
import numpy as np

from articula.solver.rig.model import Model
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.learn.weights.candidates import candidates, children_table
from articula.solver.learn.weights.skin import CandidateSkin, normal_equations

from articula.sample_scenes.tube_scans import hybrid_truth


def test_candidate_skin_equals_hybrid_skin():
    model, poses, _ = hybrid_truth(4)
    kids = children_table(model.skeleton.parents)[model.anchor]
    base, G = CandidateSkin(model.skeleton, poses).base_and_columns(
        model.rest_vertices, model.anchor, model.twist_weights.astype(np.float64), kids)
    ws = np.where(kids >= 0, model.swing_weights[np.arange(model.num_vertices)[:, None], np.maximum(kids, 0)], 0)
    assert np.abs(base + np.einsum("mvik,vk->mvi", G, ws) - hybrid_skin(model, poses)).max() < 1e-12


def _assert_candidate_skin_is_hybrid_skin(model, poses):
    """The candidate skin of the model's own anchors, twist and swing weights equals hybrid_skin (1e-12)."""
    sk = model.skeleton
    table = children_table(sk.parents)[model.anchor]
    base, G = CandidateSkin(sk, poses).base_and_columns(model.rest_vertices, model.anchor,
                                                        model.twist_weights.astype(np.float64), table)
    ws = np.where(table >= 0, model.swing_weights[np.arange(model.num_vertices)[:, None], np.maximum(table, 0)], 0)
    ref = hybrid_skin(model, poses)
    assert np.abs(base + np.einsum("mvik,vk->mvi", G, ws) - ref).max() <= 1e-12 * np.abs(ref).max()


def test_candidate_skin_follows_the_running_hemisphere_rule():
    """Opposing 170° twists of two children of one anchor (as in test_skinning): hybrid_skin flips one
    twist quaternion; the candidate skin (component-wise blend with the same rule) matches it to 1e-12.
    Includes float32 weights 0.4 + 0.6 summing to 1 + 3e-8, where the rule flips the first child."""
    from articula.sample_scenes import synthetic
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    from articula.solver.rig.skinning import twist_flips
    sk = synthetic.human_skeleton()
    model = synthetic.random_model(200, seed=4)
    fork, kids = min(((a, (c, d)) for a in range(sk.num_bones) for c in sk.children(a) for d in sk.children(a)
                      if c < d), key=lambda ap: sk.frames[ap[1][0], :, 1] @ sk.frames[ap[1][1], :, 1])
    r = np.zeros((3, sk.num_bones, 3))
    r[:, list(kids), 1] = np.radians(170.0)
    r[1, kids[1], 1] = np.radians(-120.0)
    r[2] = 0.3 * np.random.default_rng(1).normal(size=(sk.num_bones, 3))
    poses = Poses(rotvec_to_quat(r), np.zeros((3, 3)), np.ones(3))
    sel = np.flatnonzero(model.anchor == fork)
    wt = np.zeros_like(model.twist_weights)
    wt[sel, kids[0]], wt[sel, kids[1]] = 0.4, np.linspace(0.1, 0.6, len(sel))
    model = Model(model.rest_vertices, model.faces, sk, model.anchor, wt, model.swing_weights)
    assert twist_flips(model, poses)[0, sel].any()
    _assert_candidate_skin_is_hybrid_skin(model, poses)


def test_single_child_twists_at_forks_equal_hybrid_skin():
    """At an anchor with several children, candidates with twist weight (0 … 1) on one child only equal
    hybrid_skin, also for twists beyond 180° (canonical twist quaternions: a lone child is never
    flipped by the running hemisphere rule)."""
    from articula.sample_scenes import synthetic
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    sk = synthetic.human_skeleton()
    model = synthetic.random_model(200, seed=4)
    fork = next(a for a in range(sk.num_bones) if len(sk.children(a)) >= 2)
    kids = sk.children(fork)
    r = np.zeros((4, sk.num_bones, 3))
    r[:, kids[0], 1] = np.radians([0.0, 150.0, 250.0, -300.0])
    r[3] += 0.2 * np.random.default_rng(3).normal(size=(sk.num_bones, 3))
    poses = Poses(rotvec_to_quat(r), np.zeros((4, 3)), np.ones(4))
    sel = np.flatnonzero(model.anchor == fork)
    wt = np.zeros_like(model.twist_weights)
    wt[sel, kids[0]] = np.linspace(0.0, 1.0, len(sel))               # includes 0 and 1
    model = Model(model.rest_vertices, model.faces, sk, model.anchor, wt, model.swing_weights)
    _assert_candidate_skin_is_hybrid_skin(model, poses)


def test_candidate_evaluation_equals_hybrid_skin_for_every_candidate():
    """The fast candidate path (per-anchor columns: closed-form single-child twist or component-wise DLB,
    one batched product for base and swing columns; normal equations) against the slow reference:
    ``hybrid_skin`` of a model carrying each candidate's anchor, twist and random swing weights, and the
    dense einsum normal equations (1e-9 relative)."""
    model, poses, _ = hybrid_truth(3)
    sk = model.skeleton
    kids_table = children_table(sk.parents)
    skin = CandidateSkin(sk, poses)
    rng = np.random.default_rng(2)
    tried = 0
    for anchor, tw, valid, _ in candidates(model.anchor, model.twist_weights.astype(np.float64), sk.parents):
        if not valid.any():
            continue
        kids = kids_table[anchor]
        base, G = skin.base_and_columns(model.rest_vertices, anchor, tw, kids)
        ws = np.where(kids >= 0, rng.uniform(0, 0.3, size=kids.shape), 0.0)
        sw = np.zeros(model.swing_weights.shape)
        r, c = np.nonzero(kids >= 0)
        sw[r, c * 0 + kids[r, c]] = ws[r, c]
        ref_model = Model(model.rest_vertices, model.faces, sk, anchor.astype(np.int32), tw.astype(np.float32),
                          sw.astype(np.float32))
        ref_model.twist_weights = tw                       # float64 so both paths see the same numbers
        ref_model.swing_weights = sw
        ref = hybrid_skin(ref_model, poses)
        fast = base + np.einsum("mvik,vk->mvi", G, ws)
        scale = np.abs(ref).max()
        assert np.abs(fast - ref)[:, valid].max() <= 1e-9 * scale
        for a in np.unique(anchor[valid]):                 # the per-anchor columns and normal equations
            rows = np.flatnonzero(valid & (anchor == a))
            k = len(skin.kids[a])
            C = skin.columns(a, model.rest_vertices[rows].T, tw[rows][:, skin.kids[a]].T)
            assert np.abs(C[:, :3] - base[:, rows].transpose(0, 2, 1)).max() <= 1e-12 * scale
            if k == 0:
                continue
            Gr = G[:, rows, :, :k]
            r = ref[:, rows].transpose(0, 2, 1)
            H, b = normal_equations(C, r)
            H_ref, b_ref = np.einsum("mvik,mvil->vkl", Gr, Gr), np.einsum("mvik,mvi->vk", Gr, ref[:, rows])
            assert np.allclose(H, H_ref, rtol=1e-9, atol=1e-12 * np.abs(H_ref).max())
            assert np.allclose(b, b_ref, rtol=1e-9, atol=1e-12 * np.abs(b_ref).max())
        tried += 1
    assert tried > 10
