"""G3 (tree), G4 (joint placement), mirror pair names, frames, and G6 (pose conversion); the mirror pairs
themselves: test_symmetry.py."""
import numpy as np

from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Model
from articula.solver.fit.pose_init import poses_from_part_fits
from articula.solver.geometry.procrustes import fit_parts
from articula.solver.learn.segmentation import segment
from articula.solver.learn.skeleton import build_skeleton, part_adjacency, rotation_centre
from articula.solver.rig.skinning import hybrid_skin

from articula.sample_scenes.tube_scans import JOINTS, PARTS, TAILS, body, hybrid_truth, rigid_scans, rotvec_matrix


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
