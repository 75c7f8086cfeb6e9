"""Major joints of the four MPFB2 rigs (sample_scenes.bone_roles.major_joints) and their ground truth."""
import numpy as np
import pytest

from articula.sample_scenes import registered
from articula.sample_scenes.bone_roles import MAJOR_JOINT_LABELS, bone_role, major_joints
from articula.sample_scenes.mpfb_rig import RIGS
from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError

ROLE = {"shoulder": "upper_arm", "elbow": "forearm", "wrist": "wrist", "hip": "hip", "knee": "knee",
        "ankle": "ankle", "neck": "neck", "head": "head"}


@pytest.mark.parametrize("rig", RIGS)
def test_major_joints_of_every_rig(rig):
    sk = make_subject(rig).skeleton
    joints = major_joints(sk)
    assert tuple(joints) == MAJOR_JOINT_LABELS and len(set(joints.values())) == 14
    heads = sk.heads[list(joints.values())]
    for label, b in joints.items():
        assert bone_role(sk.names[b], b) == ROLE[label.split(".")[0]], (label, sk.names[b])
        if label.endswith((".L", ".R")):
            assert sk.names[b].endswith(label[-2:])
            # MakeHuman's left is +x (the subject faces -Y); a mirrored pair sits at opposite x
            assert np.sign(sk.heads[b, 0]) == (1 if label.endswith(".L") else -1), label
            other = joints[label[:-1] + ("R" if label.endswith("L") else "L")]
            assert np.allclose(sk.heads[other] * [-1, 1, 1], sk.heads[b], atol=0.02), label
        else:
            assert abs(sk.heads[b, 0]) < 0.01, label
    z = dict(zip(MAJOR_JOINT_LABELS, heads[:, 2]))
    assert z["head"] > z["neck"] > z["shoulder.L"] > z["elbow.L"] > z["hip.L"] > z["knee.L"] > z["ankle.L"]
    neck = joints["neck"]
    assert bone_role(sk.names[sk.parents[neck]]) != "neck"        # the first neck bone of a chain
    assert major_joints(sk.names) == joints                         # names work as well as a skeleton


def test_missing_roles_are_named():
    names = ["root", "spine", "neck", "head", "upperarm.L", "lowerarm.L", "hand.L"]
    with pytest.raises(ArticulaInputError, match=r"'upper_arm' on side \.R for 'shoulder\.R'"):
        major_joints(names)
    limbs = [f"{b}.{s}" for b in ("upperarm", "lowerarm", "hand", "thigh", "calf", "foot") for s in "LR"]
    assert len(major_joints(["root", "spine", "neck", "head"] + limbs)) == 14
    with pytest.raises(ArticulaInputError, match="'neck' on the midline for 'neck'"):
        major_joints(["root", "spine", "head"] + limbs)


def test_ground_truth_carries_the_major_joints():
    _, _, gt = registered.posed_sequence("default", None, 3, seed=1)
    sk = make_subject("default").skeleton
    assert list(gt["major_joint_labels"]) == list(MAJOR_JOINT_LABELS)
    assert list(gt["major_joint_bones"]) == list(major_joints(sk).values())
    assert gt["posed_heads"].shape == (3, sk.num_bones, 3)
