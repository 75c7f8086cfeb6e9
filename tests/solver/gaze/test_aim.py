"""Gaze control (solver.gaze; spec test A1): the fade is 0 outside the shot, 1 in it, monotone; at full
strength the gaze line meets a moving target within 1e-3 deg; the turn is shared 10/40/50 % to 1e-6;
frames of weight 0 and bones outside the chain are bit-identical; a target behind is limited and reported."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.gaze import aim, fade
from articula.solver.geometry.rotations import matrix_to_quat, quat_to_rotvec
from articula.solver.retarget.armature import forward, local_from_pose

from ..retarget.humanoids import humanoid, random_clip


def test_fade_is_zero_outside_one_inside_and_monotone():
    f = np.arange(0, 61)
    w = fade.shot_weights(f, 10, 50, 8)
    assert np.all(w[f < 10] == 0) and np.all(w[f > 50] == 0) and w[10] == 0 and w[50] == 0
    assert np.all(w[(f >= 18) & (f <= 42)] == 1.0)
    assert np.all(np.diff(w[10:19]) > 0) and np.all(np.diff(w[42:51]) < 0)
    assert fade.shot_weights(f, 10, 50, 0)[10] == 1.0
    with pytest.raises(ArticulaInputError, match="does not fit"):
        fade.shot_weights(f, 10, 20, 6)
    with pytest.raises(ArticulaInputError, match="before"):
        fade.shot_weights(f, 20, 10, 2)


def _setup(frames=30, seed=0):
    arm, roles = humanoid(rng=np.random.default_rng(seed))
    local = _local(arm, frames, seed)
    j = [arm.index[roles[r]] for r in ("chest", "neck", "head")]
    head = arm.rest[j[2]]
    # the gaze line: from 60 % up the head bone, along the rest -Y (facing), in the head's local axes
    origin = head[:3, :3].T @ (0.6 * (arm.tails[j[2]] - head[:3, 3]))
    direction = head[:3, :3].T @ np.array([0.0, -1.0, 0.0])
    chain = aim.GazeChain(j, np.array([0.1, 0.4, 0.5]), j[2], origin, direction, np.radians([30, 60, 80]))
    return arm, local, chain


def _local(arm, frames, seed):
    return local_from_pose(arm, random_clip(arm, frames, amplitude=0.25, seed=seed))


def _world_turn(arm, pose, local, new_local, j):
    """Rotation vector (armature space) each chain joint turned by about its own centre."""
    rel = arm.relative_rest()
    P = pose[:, arm.parents[j], :3, :3] @ rel[j][:3, :3]
    D = P @ new_local[:, j, :3, :3] @ np.linalg.inv(local[:, j, :3, :3]) @ np.swapaxes(P, 1, 2)
    return quat_to_rotvec(matrix_to_quat(D))


def test_full_strength_meets_a_moving_target_with_the_split():
    arm, local, chain = _setup()
    F = len(local)
    t = np.linspace(0, 1, F)
    targets = np.stack([1.5 * np.sin(3 * t), -2.0 + 0.5 * t, 1.2 + 0.6 * np.cos(2 * t)], axis=1)
    out, report = aim.solve(arm, local, chain, targets, np.ones(F))
    assert report["error_deg"].max() < 1e-3 and not len(report["limited"])
    pose = forward(arm, local)
    turns = np.stack([_world_turn(arm, pose, local, out, j) for j in chain.joints], axis=1)
    angles = np.linalg.norm(turns, axis=2)
    assert np.abs(angles / angles.sum(axis=1, keepdims=True) - [0.1, 0.4, 0.5]).max() < 1e-6
    axes = turns / angles[..., None]
    assert np.abs(axes - axes[:, :1]).max() < 1e-6
    others = [b for b in range(len(arm.bones)) if b not in chain.joints]
    assert np.array_equal(out[:, others], local[:, others])


def test_zero_weight_frames_are_untouched_and_partial_weight_turns_less():
    arm, local, chain = _setup(20, seed=2)
    weights = fade.shot_weights(np.arange(20), 5, 15, 3)
    targets = np.tile([0.8, -2.0, 1.6], (20, 1))
    out, report = aim.solve(arm, local, chain, targets, weights)
    assert np.array_equal(out[weights == 0], local[weights == 0])
    full, _ = aim.solve(arm, local, chain, targets, np.ones(20))
    pose = forward(arm, local)
    head = chain.joints[2]
    part = np.linalg.norm(_world_turn(arm, pose, local, out, head), axis=1)
    whole = np.linalg.norm(_world_turn(arm, pose, local, full, head), axis=1)
    inside = weights > 0
    assert np.allclose(part[inside], weights[inside] * whole[inside], rtol=1e-6)


def test_a_target_behind_is_limited_and_reported():
    arm, local, chain = _setup(6, seed=4)
    out, report = aim.solve(arm, local, chain, np.tile([0.0, 3.0, 1.5], (6, 1)), np.ones(6))
    assert len(report["limited"]) == 6
    pose = forward(arm, local)
    angles = np.linalg.norm(_world_turn(arm, pose, local, out, chain.joints[2]), axis=1)
    assert np.allclose(np.degrees(angles), 0.5 * report["reach_deg"])


def test_bad_chains_are_refused():
    arm, local, chain = _setup(2)
    chain.shares = np.array([0.5, 0.5, 0.5])
    with pytest.raises(ArticulaInputError, match="sum to 1"):
        aim.solve(arm, local, chain, np.zeros((2, 3)), np.ones(2))
    chain.shares = np.array([0.1, 0.4, 0.5])
    chain.joints = [arm.index["head"], arm.index["neck"], arm.index["chest"]]
    with pytest.raises(ArticulaInputError, match="does not hang"):
        aim.solve(arm, local, chain, np.zeros((2, 3)), np.ones(2))
