"""G3 (tree), G4 (joint placement), mirror pairs / names, frames, and G6 (pose conversion)."""
import numpy as np

from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Model
from articula.solver.fit.pose_init import poses_from_part_fits
from articula.solver.geometry.procrustes import fit_parts
from articula.solver.learn.segmentation import segment
from articula.solver.learn.skeleton import (build_skeleton, mirror_pairs, part_adjacency, rotation_centre,
                                           symmetry_planes, unequal_pairs)
from articula.solver.rig.skinning import hybrid_skin

from ..learn_data import JOINTS, PARTS, TAILS, body, hybrid_truth, rigid_scans, rotvec_matrix


def _learned(M=10, seed=0):
    scans, faces, labels, rest, Rm, tm = rigid_scans(M, seed)
    lab, _ = segment(rest, scans, faces, 8, seed=0)
    R, t = fit_parts(rest, scans, lab, 8)
    sk, order, bone_of_part, pairs = build_skeleton(rest, lab, faces, 8, R, t)
    truth = np.array([np.bincount(labels[lab == order[b]], minlength=8).argmax() for b in range(8)])
    return dict(scans=scans, faces=faces, labels=labels, rest=rest, lab=lab, R=R, t=t, sk=sk, order=order,
                pairs=pairs, truth=truth, Rm=Rm, tm=tm)


def test_tree_has_k_nodes_and_k_minus_1_edges_rooted_at_torso():
    d = _learned()
    sk = d["sk"]
    assert sk.num_bones == 8 and (sk.parents >= 0).sum() == 7
    sk.validate()                                        # parents[b] < b, frames orthonormal, Y = bone
    assert PARTS[d["truth"][0]] == "torso"
    gt_parent = {"head": "torso", "upper_arm.L": "torso", "forearm.L": "upper_arm.L", "thigh.R": "torso",
                 "upper_arm.R": "torso", "forearm.R": "upper_arm.R", "thigh.L": "torso"}
    for b in range(1, 8):
        assert PARTS[d["truth"][sk.parents[b]]] == gt_parent[PARTS[d["truth"][b]]]


def test_joints_within_5_percent_of_bone_length():
    d = _learned()
    sk = d["sk"]
    for b in range(1, 8):
        g = d["truth"][b]
        length = np.linalg.norm(TAILS[g] - JOINTS[g])
        assert np.linalg.norm(sk.heads[b] - JOINTS[g]) < 0.05 * length


def test_frames_point_to_main_child_or_far_end():
    d = _learned()
    sk = d["sk"]
    y = sk.frames[:, :, 1]
    for b in range(8):
        g = PARTS[d["truth"][b]]
        if g == "torso":                                  # main child of the root: the unpaired head
            assert PARTS[d["truth"][np.argmax(y[0] @ (sk.heads - sk.heads[0]).T /
                                              np.maximum(np.linalg.norm(sk.heads - sk.heads[0], axis=1), 1e-9))]] == "head"
        elif g.startswith("upper_arm"):
            child = int(np.flatnonzero(sk.parents == b)[0])
            axis = (sk.heads[child] - sk.heads[b]) / np.linalg.norm(sk.heads[child] - sk.heads[b])
            assert y[b] @ axis > 0.999
        else:                                              # end part: towards its far end
            g_idx = d["truth"][b]
            axis = (TAILS[g_idx] - JOINTS[g_idx]) / np.linalg.norm(TAILS[g_idx] - JOINTS[g_idx])
            assert y[b] @ axis > 0.99


def test_mirror_pairs_named_L_R():
    d = _learned()
    sk = d["sk"]
    assert len(d["pairs"]) == 3
    for l, r in d["pairs"]:
        assert sk.names[l].endswith(".L") and sk.names[r].endswith(".R")
        assert sk.names[l][:-2] == sk.names[r][:-2]
        gl, gr = PARTS[d["truth"][l]], PARTS[d["truth"][r]]
        assert gl.endswith(".L") and gr.endswith(".R") and gl[:-2] == gr[:-2]
    assert len(set(sk.names)) == 8


def test_symmetry_plane_of_a_tilted_mirror_body():
    d = _learned(M=3)
    rest = d["rest"]
    Rt = rotvec_matrix(np.array([0.1, 0.2, 0.3]))
    moved = rest @ Rt.T + [0.3, -0.2, 0.1]
    n_true = Rt @ [1.0, 0, 0]
    planes = symmetry_planes(moved)
    assert any(abs(n @ n_true) > 1 - 1e-9 for n, _, _ in planes)
    n, off, _ = next(p for p in planes if abs(p[0] @ n_true) > 0.5)
    assert abs(off - n @ [0.3, -0.2, 0.1]) < 1e-9
    assert len(mirror_pairs(moved, d["lab"], 8, (n, off, 0.0))) == 3


def test_rotation_centre_exact_for_ball_joint_and_prior_on_hinge_axis():
    rng = np.random.default_rng(0)
    c = np.array([0.2, -0.1, 0.5])
    Rp = rotvec_matrix(rng.normal(size=(6, 3)))
    tp = rng.normal(size=(6, 3))
    Rc = Rp @ rotvec_matrix(rng.normal(size=(6, 3)))
    tc = (Rp - Rc) @ c + tp                               # both maps move c alike
    assert np.linalg.norm(rotation_centre(Rp, tp, Rc, tc, c + 0.05, mu=1e-4) - c) < 1e-6
    # hinge about z: the centre's z is not determined by the motion; the prior keeps it
    Rc = Rp @ rotvec_matrix(np.outer(rng.uniform(0.3, 1, 6), [0, 0, 1.0]))
    tc = (Rp - Rc) @ c + tp
    h = rotation_centre(Rp, tp, Rc, tc, c + [0, 0, 0.05])
    assert np.linalg.norm(h[:2] - c[:2]) < 1e-3 and abs(h[2] - (c[2] + 0.05)) < 1e-9


def test_part_adjacency_counts_cross_edges():
    d = _learned(M=3)
    C = part_adjacency(d["labels"], d["faces"], 8)
    assert np.allclose(C, C.T) and C[0, 1] > 0 and C[1, 2] == 0 and C[2, 3] > 0


def test_pose_conversion_reproduces_rigid_fit():
    """Re-posing with the converted rotations (and exact joint centres) gives the per-part rigid maps."""
    d = _learned()
    sk = d["sk"]
    sk.heads[1:] = JOINTS[d["truth"][1:]]                  # exact rotation centres
    W = d["R"][:, d["order"]]
    tau = d["t"][:, d["order"]]
    poses = poses_from_part_fits(sk, W, tau)
    poses.validate(8)
    Rm, tm = forward_kinematics(sk, poses)
    assert np.abs(Rm - W).max() < 1e-9 and np.abs(tm - tau).max() < 1e-9
    # and the rigid (binary-weight) model reproduces the scans
    bone_of_part = np.argsort(d["order"])
    V = len(d["rest"])
    model = Model(d["rest"], d["faces"], sk, bone_of_part[d["lab"]], np.zeros((V, 8)), np.zeros((V, 8)))
    assert np.abs(hybrid_skin(model, poses) - d["scans"]).max() < 1e-9


def test_consistent_pairs_keeps_only_structural_mirror_pairs():
    from articula.solver.learn.skeleton import consistent_pairs
    #        0 root; 1, 2 thighs (siblings); 3 under 1, 4 under 2 (shins); 5 neck under 0 (small); 6 arm
    parent = np.array([-1, 0, 0, 1, 2, 0, 0])
    sizes = np.array([900, 300, 310, 200, 190, 60, 280])
    votes = {(5, 6): 3,            # neck vs arm: siblings but sizes 60 vs 280 -> rejected
             (1, 2): 1,            # thighs
             (4, 3): 2,            # shins, voted right-before-left: left follows the parents' pair
             (0, 5): 1,            # root never pairs
             (3, 6): 1}            # parents 1 and 0 are not a pair -> rejected
    assert consistent_pairs(votes, parent, sizes) == [(1, 2), (3, 4)]


def test_joint_local_fits_place_smoothly_skinned_joints():
    """Blended skin near the joints biases whole-part rigid fits; the joint-local robust fits (scans given)
    put every joint of the smoothly skinned tube body within 2 mm (whole parts: up to 7.5 mm)."""
    for seed in range(2):
        model, _, scans = hybrid_truth(M=12, seed=seed)
        rest = model.rest_vertices
        _, faces, labels = body()
        R, t = fit_parts(rest, scans, labels, 8)
        whole, order, _, _ = build_skeleton(rest, labels, faces, 8, R, t, symmetry=False)
        local, order2, _, _ = build_skeleton(rest, labels, faces, 8, R, t, symmetry=False, scans=scans)
        assert np.array_equal(order, order2)
        e_whole = np.linalg.norm(whole.heads[1:] - JOINTS[order[1:]], axis=1)
        e_local = np.linalg.norm(local.heads[1:] - JOINTS[order[1:]], axis=1)
        assert e_local.max() < 2e-3 and e_whole.max() > 2.5e-3 and e_local.mean() < 0.5 * e_whole.mean()


def test_joint_local_fits_match_whole_part_fits_on_rigid_parts():
    """Rigid parts: every vertex fits its part exactly, so the weights change nothing."""
    d = _learned()
    sk, order, _, pairs = build_skeleton(d["rest"], d["lab"], d["faces"], 8, d["R"], d["t"], scans=d["scans"])
    assert np.array_equal(order, d["order"]) and pairs == d["pairs"]
    assert np.abs(sk.heads - d["sk"].heads).max() < 1e-9
    assert np.abs(sk.heads[1:] - JOINTS[d["truth"][1:]]).max() < 1e-3


def test_consistent_pairs_rejects_parts_cut_differently():
    """Mirror parts whose vertex counts differ by more than MIRROR_SIZE_RATIO were cut at different places
    (MakeHuman at 19 parts: a left shin part with the heel, 371 vertices, vs the right shin alone, 240)."""
    from articula.solver.learn.skeleton import consistent_pairs
    parent = np.array([-1, 0, 0, 1, 2])
    assert consistent_pairs({(1, 2): 2, (3, 4): 2}, parent, np.array([900, 342, 342, 371, 240])) == [(1, 2)]
    assert consistent_pairs({(1, 2): 2, (3, 4): 2}, parent, np.array([900, 342, 342, 371, 340])) == [(1, 2), (3, 4)]


def test_unequal_pairs_flags_mirror_bones_of_different_length():
    #   0 root; 1 / 2 mirrored upper limbs continuing into 3 / 4
    parents = np.array([-1, 0, 0, 1, 2])
    heads = np.array([[0, 0, 1.0], [0.1, 0, 1], [-0.1, 0, 1], [0.1, 0, 0.6], [-0.1, 0, 0.62]])
    tails = np.array([[0, 0, 1.5], heads[3], heads[4], [0.1, 0, 0.2], [-0.1, 0, 0.2]])
    assert unequal_pairs(heads, tails, parents, [(1, 2), (3, 4)]) == []          # 0.40 vs 0.38 m: within 10 %
    heads[4, 2] = tails[2, 2] = 0.7                                              # 0.40 vs 0.30 m
    assert unequal_pairs(heads, tails, parents, [(1, 2), (3, 4)]) == [(1, 2)]    # end bones are not compared


def test_mirror_pairs_from_the_vertex_mirror_map():
    """With the mesh's vertex mirror map the pairs come from it: the same pairs and names as from the
    symmetry planes on the symmetric rest mesh, and the same parts paired from every posed scan, where no
    plane reflects the whole body."""
    from articula.solver.learn.segmentation import mirror_map
    from articula.solver.learn.skeleton import MAP_COVERAGE, map_pair_votes
    d = _learned()
    mirror = mirror_map(d["rest"], d["scans"], d["faces"])
    assert mirror is not None and np.mean(mirror >= 0) >= MAP_COVERAGE
    sk, order, bone_of_part, pairs = build_skeleton(d["rest"], d["lab"], d["faces"], 8, d["R"], d["t"],
                                                    mirror=mirror)
    assert pairs == d["pairs"] and sk.names == d["sk"].names
    expected = {frozenset((int(d["order"][l]), int(d["order"][r]))) for l, r in d["pairs"]}
    for m in range(len(d["scans"])):           # (a scan's own rigid turn may flip which side is +X)
        assert {frozenset(p) for p in map_pair_votes(d["scans"][m], d["lab"], 8, mirror)} == expected, m
    broken = np.where(np.arange(len(mirror)) % 2 == 0, mirror, -1)      # half the map: planes instead
    assert build_skeleton(d["rest"], d["lab"], d["faces"], 8, d["R"], d["t"], mirror=broken)[3] == d["pairs"]
