"""The start-pose set and its transfer onto rigs by segment direction (solver.tracking.start_poses).

References: the stored joint positions themselves (each aimed segment of the posed rig, by forward
kinematics, must point along the stored direction), and the body measures of the set (independent of
the aiming code)."""
import json
import os

import numpy as np
import pytest

from articula.sample_scenes.registered import posed_sequence
from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError
from articula.solver.learn.role_names import names_for
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Model, Skeleton, frames_from_bones
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.roles import PARENT, role_bones
from articula.solver.tracking.start_poses import (POSE_ROLES, START_POSES_PATH, PoseSet, RigPoser,
                                                  load_pose_set, role_direction)

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


def _segment_errors(sk, poser, ps, segments=SEGMENTS):
    poses = poser.poses(ps)
    Rm, tm = forward_kinematics(sk, poses)
    H = np.einsum("nbij,bj->nbi", Rm, sk.heads) + tm
    J = ps.joints @ poser.frame.T
    out = {}
    for a, b in segments:
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


def test_chest_rooted_skeleton_as_learned_rigs_are():
    """A rig rooted at its chest (as learn_rig's often are: the spine and hips hang from it, reversed), its
    parts' axes its own and no hip or shoulder girdle bones: the limbs and the thigh and shoulder lines
    still point as the pose's."""
    sk = make_subject("cmu_mb").skeleton
    roles = {b: r for r, b in role_bones(sk.names).items() if not r.startswith(("hip.", "shoulder."))}
    names = [roles.get(b, f"part_{b:02d}") for b in range(sk.num_bones)]      # learn_rig's naming
    chest = _rerooted(Skeleton(names, sk.parents, sk.heads, sk.tails, sk.frames), names.index("chest"))
    poser = RigPoser(chest)
    assert chest.parents[poser.roles["hips"]] == poser.roles["spine"]
    ps = load_pose_set().take(slice(0, 60))
    errors = _segment_errors(chest, poser, ps)
    assert len(errors) == len(SEGMENTS) and max(errors.values()) < 0.5, errors
    lines = _segment_errors(chest, poser, ps, (("thigh.R", "thigh.L"), ("upper_arm.R", "upper_arm.L")))
    assert max(lines.values()) < 10.0, lines


def test_learned_rig_keeps_its_pelvis_below_its_chest():
    """The skeleton learn_rig gave for a mixamo body (``data/learned_mixamo_skeleton.json``): rooted at the
    chest, its hips part hanging from it and pointing down to the thigh joints, no spine part.  Posed by
    its own rest joints, it stays at rest (its hips part, aimed by its own axis along the pose's hips-to-
    spine direction, turned the thighs above the chest, 0.4-0.6 m off)."""
    with open(os.path.join(os.path.dirname(__file__), "data", "learned_mixamo_skeleton.json")) as f:
        data = json.load(f)
    sk = Skeleton(data["names"], np.array(data["parents"]), np.array(data["heads"]), np.array(data["tails"]),
                  np.array(data["frames"]))
    poser = RigPoser(sk)
    assert sk.parents[poser.roles["hips"]] == poser.roles["chest"] and "spine" not in poser.roles
    J = np.stack([_rest_joint(sk, poser.roles, r) for r in POSE_ROLES])
    body = (J - J[POSE_ROLES.index("hips")]) @ poser.frame
    Rm, tm = forward_kinematics(sk, poser.poses(PoseSet(body[None], np.zeros(1), np.zeros(1))))
    posed = np.einsum("bij,bj->bi", Rm[0], sk.heads) + tm[0]
    error = np.linalg.norm(posed - sk.heads, axis=1)
    assert error.max() < 0.05, dict(zip(sk.names, error.round(3)))


def _rest_joint(sk, roles, role):
    """The rest position of pose role ``role`` (ends: the bone's tail, or its chain's last bone's; a role
    the rig lacks: its parent's joint)."""
    if role.endswith(".end"):
        base = role[:-4]
        while base not in roles:
            base = PARENT[base]
        return sk.tails[roles[base]]
    while role not in roles:
        role = PARENT[role]
    return sk.heads[roles[role]]


def _rerooted(sk, root):
    """``sk`` with part ``root`` as its root: every edge on the way reversed (a part's joint is the one
    it shares with its new parent), bones in breadth-first order, each with an axis of its own (random)."""
    nbrs = {b: set() for b in range(sk.num_bones)}
    for b in range(1, sk.num_bones):
        nbrs[b].add(int(sk.parents[b]))
        nbrs[int(sk.parents[b])].add(b)
    order, parent, head = [root], {root: -1}, {root: sk.heads[root]}
    for x in order:
        for y in sorted(nbrs[x] - set(parent)):
            parent[y] = x
            head[y] = sk.heads[y] if sk.parents[y] == x else sk.heads[x]
            order.append(y)
    index = {b: i for i, b in enumerate(order)}
    heads = np.array([head[b] for b in order])
    axes = np.random.default_rng(0).normal(size=heads.shape)        # a learned part's axis is its own
    tails = heads + 0.1 * axes / np.linalg.norm(axes, axis=1, keepdims=True)
    return Skeleton([sk.names[b] for b in order], [index[parent[b]] if parent[b] >= 0 else -1 for b in order],
                    heads, tails, frames_from_bones(heads, tails))


@pytest.mark.parametrize("rig", ["cmu_mb", "game_engine"])
def test_true_joint_positions_give_back_the_true_surface(rig):
    """A pose given by the true joints of random range-of-motion frames (their positions in the body
    frame: up = world Z, left = thigh line) makes the rig's surface within 20 mm of the truth on average
    after a rigid alignment (only the twists about the segments are not given; measured 7-9 mm)."""
    verts, _, gt = posed_sequence(rig=rig, shape="female", n_poses=7, motion="rom", skin="hybrid", seed=11,
                                  amplitude=0.5)
    sk = Skeleton(gt["bone_names"], gt["parents"], gt["heads"], gt["tails"], gt["frames"])
    model = Model(gt["rest_vertices"], gt["faces"], sk, gt["anchor"], gt["twist_weights"], gt["swing_weights"])
    poser = RigPoser(sk)
    J = np.stack([_true_joint(gt, poser.roles, r) for r in POSE_ROLES], axis=1)
    left = J[:, POSE_ROLES.index("thigh.L")] - J[:, POSE_ROLES.index("thigh.R")]
    left[:, 2] = 0.0
    left /= np.linalg.norm(left, axis=1, keepdims=True)
    up = np.array([0.0, 0.0, 1.0])
    E = np.stack([left, np.cross(up, left), np.broadcast_to(up, left.shape)], axis=2)
    joints = np.einsum("fji,frj->fri", E, J - J[:, :1])
    posed = hybrid_skin(model, poser.poses(PoseSet(joints, np.zeros(len(J)), np.zeros(len(J)))))
    for V, truth in zip(posed[::3], verts[::3]):
        mv, mt = V.mean(axis=0), truth.mean(axis=0)
        U, _, Vt = np.linalg.svd((truth - mt).T @ (V - mv))
        R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        assert np.linalg.norm((V - mv) @ R.T + mt - truth, axis=1).mean() < 0.020


def _true_joint(gt, roles, role):
    """The posed position of pose role ``role`` (ends: the bone's tail; a role the rig lacks: its parent's
    joint, as a CMU clip's hip joint is its hips joint)."""
    if role.endswith(".end"):
        return gt["posed_tails"][:, roles[role[:-4]]]
    while role not in roles:
        role = PARENT[role]
    return gt["posed_heads"][:, roles[role]]


def test_rig_without_limb_roles_is_refused():
    sk = make_subject("cmu_mb").skeleton
    anonymous = Skeleton([f"part_{i:02d}" for i in range(sk.num_bones)], sk.parents, sk.heads, sk.tails, sk.frames)
    with pytest.raises(ArticulaInputError, match="no bone for the role"):
        RigPoser(anonymous)
