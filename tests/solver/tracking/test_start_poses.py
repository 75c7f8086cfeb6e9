"""The start-pose set and its transfer onto rigs by segment direction (solver.tracking.start_poses).

References: the stored joint positions themselves (each aimed segment of the posed rig, by forward
kinematics, must point along the stored direction), and the body measures of the set (independent of
the aiming code)."""
import os

import numpy as np
import pytest

from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError
from articula.solver.learn.role_names import names_for
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Skeleton
from articula.solver.roles import role_bones
from articula.solver.tracking.start_poses import (POSE_ROLES, START_POSES_PATH, RigPoser, load_pose_set,
                                                  role_direction)

SEGMENTS = [("spine", "chest"), ("chest", "neck")] + [(f"{a}.{s}", f"{b}.{s}") for s in "LR" for a, b in (
    ("upper_arm", "forearm"), ("forearm", "hand"), ("thigh", "shin"), ("shin", "foot"))]


def test_shipped_set_is_small_and_broad():
    ps = load_pose_set()
    assert 100 <= len(ps) <= 300 and os.path.getsize(START_POSES_PATH) < 100_000
    J = ps.joints
    ix = POSE_ROLES.index
    feet = np.minimum(J[:, ix("foot.L"), 2], J[:, ix("foot.R"), 2])
    hands_up = np.maximum(J[:, ix("hand.L.end"), 2], J[:, ix("hand.R.end"), 2]) > J[:, ix("head.end"), 2]
    crouched = J[:, ix("head.end"), 2] - feet < 0.75                  # head less than 3/4 height above feet
    bent = role_direction(J, "hips", "neck")[:, 2] < np.cos(np.radians(40))
    arm_out = np.abs(role_direction(J, "upper_arm.L", "hand.L")[:, 2]) < 0.3
    leg_up = np.maximum(J[:, ix("foot.L"), 2], J[:, ix("foot.R"), 2]) - feet > 0.2
    for kind, mask in (("hands above the head", hands_up), ("crouching", crouched), ("bent forward", bent),
                       ("arm out", arm_out), ("one leg raised", leg_up)):
        assert mask.sum() >= 3, kind
    assert np.allclose(J[:, ix("hips")], 0.0)


def _segment_errors(sk, poser, ps):
    poses = poser.poses(ps)
    Rm, tm = forward_kinematics(sk, poses)
    H = np.einsum("nbij,bj->nbi", Rm, sk.heads) + tm
    J = ps.joints @ poser.frame.T
    out = {}
    for a, b in SEGMENTS:
        if a in poser.roles and b in poser.roles:
            d = H[:, poser.roles[b]] - H[:, poser.roles[a]]
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            out[a, b] = np.degrees(np.arccos(np.clip((d * role_direction(J, a, b)).sum(axis=1), -1, 1))).max()
    return out


@pytest.mark.parametrize("rig", ["cmu_mb", "game_engine", "default"])
def test_every_segment_points_along_the_pose(rig):
    sk = make_subject(rig).skeleton
    ps = load_pose_set().take(slice(0, 60))
    errors = _segment_errors(sk, RigPoser(sk), ps)
    assert len(errors) == len(SEGMENTS)
    assert max(errors.values()) < 0.5, errors


def test_role_named_skeleton_as_learn_rig_names_it():
    sk = make_subject("cmu_mb").skeleton
    named = Skeleton(names_for(sk, role_bones(sk.names)), sk.parents, sk.heads, sk.tails, sk.frames)
    assert "thigh.L" in named.names and "upper_arm.R" in named.names
    errors = _segment_errors(named, RigPoser(named), load_pose_set().take(slice(0, 40)))
    assert len(errors) == len(SEGMENTS) and max(errors.values()) < 0.5, errors


def test_rig_without_limb_roles_is_refused():
    sk = make_subject("cmu_mb").skeleton
    anonymous = Skeleton([f"part_{i:02d}" for i in range(sk.num_bones)], sk.parents, sk.heads, sk.tails, sk.frames)
    with pytest.raises(ArticulaInputError, match="no bone for the role"):
        RigPoser(anonymous)
