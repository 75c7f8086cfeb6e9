"""Subjects: MPFB2 rigs on shaped bodies, LBS weights, hybrid anchors/weights (sample_scenes.subjects)."""
import numpy as np
import pytest

from articula.sample_scenes import subjects
from articula.sample_scenes.bone_roles import skeleton_roles
from articula.sample_scenes.hybrid_weights import anchors_from_lbs, lift_table
from articula.sample_scenes.mpfb_rig import side_name
from articula.solver.errors import ArticulaInputError

RIGS = ["cmu_mb", "game_engine", "default", "mixamo"]
# MPFB places cmu_mb/game_engine joints by mirrored cubes; default/mixamo use some vertices that are
# not exact mirror pairs (measured: 1 mm and 6 mm).
SYMMETRY_TOL = {"cmu_mb": 1e-9, "game_engine": 1e-9, "default": 2e-3, "mixamo": 1e-2}


@pytest.fixture(scope="module", params=RIGS)
def subject(request):
    return subjects.make_subject(request.param)


def test_counts_and_ground(subject):
    assert subject.vertices.shape == (13380, 3)
    assert subject.quads.shape == (13378, 4) and subject.triangles.shape == (26756, 3)
    assert subject.vertices[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    assert 1.5 < subject.vertices[:, 2].max() < 1.8


def test_skeleton_order_and_names(subject):
    sk = subject.skeleton
    sk.validate()
    assert sk.parents[0] == -1 and all(0 <= sk.parents[b] < b for b in range(1, sk.num_bones))
    lefts = [n for n in sk.names if n.endswith(".L")]
    assert len(lefts) >= 5 and sorted(n[:-2] for n in lefts) == sorted(n[:-2] for n in sk.names if n.endswith(".R"))
    assert not any(k in n.lower() for n in sk.names for k in ("left", "right", "mixamorig"))


def test_joints_inside_body_and_mirrored(subject):
    sk, v = subject.skeleton, subject.vertices
    lo, hi = v.min(axis=0) - 0.005, v.max(axis=0) + 0.005
    assert ((sk.heads >= lo) & (sk.heads <= hi)).all()
    index = {n: i for i, n in enumerate(sk.names)}
    tol = SYMMETRY_TOL[subject.rig]
    for name, i in index.items():
        if name.endswith(".L"):
            j = index[name[:-2] + ".R"]
            assert np.abs(sk.heads[i] * [-1, 1, 1] - sk.heads[j]).max() <= tol, name
            assert sk.heads[i, 0] > -tol                      # the character's left is +X
    # the rig is anatomically plausible: head above hips above knees above feet
    roles = skeleton_roles(sk.names)
    z = {r: np.mean([sk.heads[b, 2] for b in range(sk.num_bones) if roles[b] == r]) for r in set(roles)}
    assert z["head"] > z["upper_arm"] > z["hip"] > z["knee"] > z["ankle"]


def test_every_limb_role_is_found(subject):
    roles = skeleton_roles(subject.skeleton.names)
    for role in ("spine", "neck", "head", "upper_arm", "forearm", "wrist", "hip", "knee", "ankle", "finger"):
        assert role in roles, role
    for role in ("upper_arm", "forearm", "hip", "knee", "ankle"):
        assert roles.count(role) == 2, role


def test_lbs_weights(subject):
    W = subject.lbs_weights
    assert W.shape == (13380, subject.skeleton.num_bones)
    assert W.min() >= 0 and np.allclose(W.sum(axis=1), 1)


def test_hybrid_model_is_valid_and_not_the_linear_case(subject):
    model = subject.hybrid_model()
    model.validate()
    assert (model.swing_weights.sum(axis=1) > 0).sum() > 1000          # vertices really blend
    diff = np.abs(model.twist_weights - model.swing_weights).max(axis=1)
    assert (diff > 0.1).sum() > 200                                     # twist ramp on the arms
    plain = subject.hybrid_model(twist_ramp=False)
    assert np.array_equal(plain.twist_weights, plain.swing_weights)


def test_anchor_rule_on_a_small_chain():
    """Chain 0 -> 1 -> 2 -> 3 plus a branch 0 -> 4; weights chosen so the answer is known by hand."""
    parents = np.array([-1, 0, 1, 2, 0])
    W = np.array([[0, 1.0, 0, 0, 0],          # one bone only: rigid on bone 1
                  [0, 0.6, 0.4, 0, 0],        # across joint 1-2: anchor 1, weight 0.4 on 2
                  [0, 0.2, 0.5, 0.3, 0],      # coverage(1) = 0.7, coverage(2) = 0.8 -> anchor 2, 0.3 on 3
                  [0.5, 0.1, 0.1, 0, 0.3],    # anchor 0; bone 2's weight is lifted onto 1
                  [0, 0, 0, 0, 1.0]])
    anchor, blend, moved = anchors_from_lbs(W, parents)
    assert anchor.tolist() == [1, 1, 2, 0, 4]
    expect = np.zeros_like(W)
    expect[1, 2] = 0.4
    expect[2, 3] = 0.3                        # bone 1's 0.2 joins the anchor's own weight
    expect[3, 1], expect[3, 4] = 0.2, 0.3
    assert np.allclose(blend, expect)
    assert np.allclose(moved, [0, 0, 0.2, 0.1, 0])
    assert lift_table(parents)[0].tolist() == [0, 1, 1, 1, 4]


def test_max_influences_keeps_the_largest():
    parents = np.array([-1, 0, 0, 0])
    W = np.array([[0.1, 0.5, 0.3, 0.1]])
    anchor, blend, _ = anchors_from_lbs(W, parents, max_influences=2)
    assert anchor[0] == 0 and np.allclose(blend, [[0, 0.5 / 0.9, 0.3 / 0.9, 0]])


def test_determinism_and_shapes():
    a = subjects.make_subject("cmu_mb", "female", seed=3)
    b = subjects.make_subject("cmu_mb", "female", seed=3)
    c = subjects.make_subject("cmu_mb", "female", seed=4)
    assert np.array_equal(a.vertices, b.vertices) and a.macros == b.macros
    assert a.macros["gender"] == 0.0 == c.macros["gender"]
    assert np.abs(a.vertices - c.vertices).max() > 0.01
    d = subjects.make_subject("cmu_mb", {"gender": 0.0})
    assert d.macros == subjects.resolve_macros("female")


def test_roles_of_look_alike_names():
    from articula.sample_scenes.bone_roles import bone_role
    assert bone_role("pelvis.L") == "hip_girdle" and bone_role("HipJoint.R") == "hip_girdle"
    assert bone_role("pelvis") == "spine" and bone_role("Hips", 0) == "root"
    assert bone_role("HandFinger1.L") == "finger" and bone_role("Hand.L") == "wrist"
    assert bone_role("lowerarm02.L") == "twist_arm" and bone_role("lowerarm01.L") == "forearm"
    assert bone_role("Leg.R") == "knee" and bone_role("UpLeg.R") == "hip" and bone_role("ToeBase.L") == "toe"
    assert bone_role("levator03.L") == "other"


@pytest.mark.parametrize("name, expect", [("LeftArm", "Arm.L"), ("RHipJoint", "HipJoint.R"),
                                          ("upperarm_l", "upperarm.L"), ("mixamorig:RightHand", "Hand.R"),
                                          ("finger1-2.L", "finger1-2.L"), ("Hips", "Hips"), ("LowerBack", "LowerBack")])
def test_side_names(name, expect):
    assert side_name(name) == expect


def test_shape_strings_and_errors():
    assert subjects.parse_shape("female, heavy,age=0.7") == {"gender": 0.0, "weight": 0.9, "age": 0.7}
    with pytest.raises(ArticulaInputError, match="unknown preset"):
        subjects.parse_shape("female,fat")
    with pytest.raises(ArticulaInputError, match="not a number"):
        subjects.parse_shape("age=old")
    with pytest.raises(ArticulaInputError, match="unknown rig"):
        subjects.make_subject("biped")


def test_twist_ramp_spreads_a_hand_twist_along_the_forearm():
    """Twisting only the hand by 90 degrees about its own axis: with the ramp, forearm skin turns by
    an amount that grows from the elbow (none) to the wrist; without it the forearm skin away from the
    wrist (no LBS weight on the hand) stays put."""
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    from articula.solver.rig.skinning import hybrid_skin
    subject = subjects.make_subject("cmu_mb")
    sk = subject.skeleton
    fore, hand = sk.names.index("ForeArm.L"), sk.names.index("Hand.L")
    rot = np.zeros((1, sk.num_bones, 4))
    rot[..., 0] = 1
    rot[0, hand] = rotvec_to_quat([0, np.pi / 2, 0])
    poses = Poses(rot, np.zeros((1, 3)), np.ones(1))
    ramped, plain = subject.hybrid_model(), subject.hybrid_model(twist_ramp=False)
    rows = np.flatnonzero(ramped.anchor == fore)      # a pure twist has no swing: swing weights do nothing
    axis = sk.tails[fore] - sk.heads[fore]
    t = (subject.vertices[rows] - sk.heads[fore]) @ axis / (axis @ axis)

    def turn(model):
        posed = hybrid_skin(model, poses)[0, rows]
        radial = lambda x: x - sk.heads[fore] - np.outer((x - sk.heads[fore]) @ axis / (axis @ axis), axis)
        a, b = radial(subject.vertices[rows]), radial(posed)
        return np.degrees(np.arccos(np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1), -1, 1)))

    unweighted = ramped.swing_weights[rows, hand] == 0
    assert np.abs(turn(plain)[unweighted]).max() < 1e-4      # degrees (arccos rounding)
    angle = turn(ramped)
    assert angle[unweighted].max() > 30                      # ... while the ramp turns them
    near, mid, far = angle[t < 0.25], angle[(t > 0.45) & (t < 0.7)], angle[t > 0.85]
    assert len(near) > 10 and len(mid) > 10 and len(far) > 10
    assert near.max() < 1 and 10 < np.median(mid) < 60 and np.median(far) > np.median(mid) + 15
