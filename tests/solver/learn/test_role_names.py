"""Human role names of learned skeletons (solver.learn.role_names): MakeHuman scans learned end to end
get role names whose joints are the true ones, hand-made rigs in any up axis and mirror are recognised
with the character's sides, and non-humans (the skinning_gt wolf, a tube body) keep their part names."""
import glob
import os

import numpy as np
import pytest

from articula.sample_scenes.registered import posed_sequence
from articula.solver.formats.obj import read_obj
from articula.solver.learn.pipeline import learn_rig
from articula.solver.learn.role_names import REQUIRED, names_for, recognise, role_names
from articula.solver.roles import ROLES
from articula.solver.rig.model import Skeleton
from articula.solver.rig.names import problem

from ...conftest import SHARED_DATA
from articula.sample_scenes.tube_scans import hybrid_truth

# role -> the MakeHuman ground truth's major joint at the role bone's head
JOINT_OF = {"upper_arm": "shoulder", "forearm": "elbow", "hand": "wrist", "thigh": "hip", "shin": "knee",
            "foot": "ankle"}


@pytest.fixture(scope="module")
def makehuman():
    """A MakeHuman range of motion (10 scans) learned up to its first poses (no rounds: the skeleton)."""
    scans, faces, gt = posed_sequence("cmu_mb", None, 10, "rom", "lbs", seed=0)
    return learn_rig(scans, faces, max_iterations=0, workers=2), gt


def _skeleton(gt, rotation=np.eye(3)):
    heads, tails = gt["heads"] @ rotation.T, gt["tails"] @ rotation.T
    frames = np.einsum("ij,bjk->bik", rotation, gt["frames"])
    return Skeleton(gt["bone_names"], gt["parents"], heads, tails, frames)


def test_learned_makehuman_bones_are_named_by_role_at_the_true_joints(makehuman):
    res, gt = makehuman
    names = res.model.skeleton.names
    assert res.report["bone_names"]["scheme"] == "roles"
    assert set(REQUIRED) <= set(names) and len(set(names)) == len(names)
    assert all(problem(n) is None for n in names)
    assert all(n in ROLES or n.startswith("part_") for n in names)
    heads = dict(zip(names, res.model.skeleton.heads))
    true = {str(k): gt["posed_heads"][res.report["rest_scan"], b]
            for k, b in zip(gt["major_joint_labels"], gt["major_joint_bones"])}
    checked = 0
    for role, joint in JOINT_OF.items():
        for side in ("L", "R"):
            if f"{role}.{side}" in heads:
                other = "R" if side == "L" else "L"
                d = np.linalg.norm(heads[f"{role}.{side}"] - true[f"{joint}.{side}"])
                assert d < 0.05 and d < np.linalg.norm(heads[f"{role}.{side}"] - true[f"{joint}.{other}"]) / 3
                checked += 1
    assert checked >= 8
    assert np.linalg.norm(heads["neck"] - true["neck"]) < 0.05
    # mirror pairs are renamed with their bones
    assert all(set(pair) <= set(names) for pair in res.report["mirror_pairs"])
    assert ("thigh.L", "thigh.R") in [tuple(sorted(p)) for p in res.report["mirror_pairs"]]


@pytest.mark.parametrize("rig", ["cmu_mb", "default"])
@pytest.mark.parametrize("up", ["Z", "Y", "mirrored"])
def test_hand_made_rigs_in_any_up_axis(rig, up):
    """The generating rigs (Z up, facing -Y): also stood Y up (OBJ files) and mirrored (x -> -x: the
    character's sides swap)."""
    _, _, gt = posed_sequence(rig, None, 2, "rom", "lbs", seed=0)
    rotation = {"Z": np.eye(3), "Y": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
                "mirrored": np.diag([-1.0, 1, 1])}[up]
    sk = _skeleton(gt, rotation)
    if up == "mirrored":
        sk.frames[:, :, 0] *= -1            # keep the frames right-handed; only the geometry matters
    roles, why = recognise(sk)
    assert why == "humanoid" and set(REQUIRED) <= set(roles)
    swap = up == "mirrored"
    for role in ("thigh", "shin", "upper_arm", "forearm"):
        for side in ("L", "R"):
            name = sk.names[roles[f"{role}.{side}"]]
            assert name.endswith("." + ({"L": "R", "R": "L"}[side] if swap else side)), (role, side, name)


def test_names_follow_the_character_and_stay_unique():
    sk = Skeleton(["root", "part_01.L", "part_01.R", "part_03.L", "part_03.R"], [-1, 0, 0, 1, 2],
                  np.zeros((5, 3)), np.ones((5, 3)), np.tile(np.eye(3), (5, 1, 1)))
    names = names_for(sk, {"hips": 0, "thigh.L": 2, "thigh.R": 1})
    # the learned pairs' .L was the character's right: the unnamed pair swaps its suffixes too
    assert names == ["hips", "thigh.R", "thigh.L", "part_03.R", "part_03.L"]


@pytest.mark.skipif(not os.path.isdir(os.path.join(SHARED_DATA, "skinning_gt", "wolf-all")),
                    reason="skinning_gt wolf not present")
def test_the_wolf_keeps_its_part_names():
    d = os.path.join(SHARED_DATA, "skinning_gt", "wolf-all")
    files = sorted(glob.glob(os.path.join(d, "poses-*", "*.obj")))[::3]
    scans = np.stack([read_obj(f).vertices for f in files])
    faces = read_obj(files[0]).triangles()
    res = learn_rig(scans, faces, max_iterations=0, workers=2)
    assert res.report["bone_names"]["scheme"] == "parts"
    assert all(n == "root" or n.startswith("part_") for n in res.model.skeleton.names)


def test_a_tube_body_and_the_option_off_keep_part_names():
    model, _, scans = hybrid_truth(4, seed=1)
    res = learn_rig(scans, model.faces, parts=8, max_iterations=0)
    assert res.report["bone_names"]["scheme"] == "parts" and role_names(res.model.skeleton) is None
    res = learn_rig(scans, model.faces, parts=8, max_iterations=0, name_roles=False)
    assert res.report["bone_names"] == dict(scheme="parts", roles=0, why="name_roles is off")
