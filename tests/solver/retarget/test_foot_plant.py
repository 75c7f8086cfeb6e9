"""Foot-contact clean-up (solver.retarget.foot_plant): contact detection on a known trajectory, the
two-bone IK against its closed-form properties, and planting on a retargeted clip whose target legs
have other proportions than the source's."""
import numpy as np

from articula.solver.retarget import foot_plant
from articula.solver.retarget.armature import forward, local_matrices, world_pose
from articula.solver.geometry.rotations import quat_to_matrix, rotvec_to_matrix
from articula.solver.retarget.mapping import Mapping
from articula.solver.retarget.solve import RetargetOptions, retarget_clip

from .humanoids import humanoid


def test_contacts_are_the_slow_low_stretches():
    F = 100
    ankle = np.zeros((F, 3))
    ankle[:, 1] = np.linspace(0.0, 2.0, F)                       # moving 2 m in 100 frames at 50 fps: 1 m/s
    ankle[20:40, 1] = ankle[20, 1]                               # planted
    ankle[60:70, 1] = ankle[60, 1]
    ankle[60:70, 2] = 0.3                                        # still, but in the air
    (first, last), = foot_plant.contacts(ankle, leg=0.9, fps=50.0)
    assert 20 <= first <= 22 and 37 <= last <= 39      # edges blurred by the speed's smoothing


def test_two_bone_ik_reaches_the_goal_and_keeps_lengths_and_knee_plane():
    rng = np.random.default_rng(0)
    F = 50
    hip = rng.normal(size=(F, 3))
    knee = hip + rng.normal(size=(F, 3)) * 0.3
    ankle = knee + rng.normal(size=(F, 3)) * 0.3
    goal = hip + 0.8 * (ankle - hip) + rng.normal(size=(F, 3)) * 0.02
    l1, l2 = np.linalg.norm(knee - hip, axis=1), np.linalg.norm(ankle - knee, axis=1)
    ok = np.linalg.norm(goal - hip, axis=1) < 0.99 * (l1 + l2)
    ok &= np.linalg.norm(goal - hip, axis=1) > 1.01 * np.abs(l1 - l2)
    R1, R2 = foot_plant._two_bone(hip, knee, ankle, goal)
    new_knee = hip + np.einsum("fij,fj->fi", R1, knee - hip)
    new_ankle = new_knee + np.einsum("fij,fj->fi", R2 @ R1, ankle - knee)
    assert np.abs(new_ankle - goal)[ok].max() < 1e-9
    assert np.abs(np.linalg.norm(new_knee - hip, axis=1) - l1).max() < 1e-9
    normal = np.cross(knee - hip, goal - hip)
    assert np.abs(np.einsum("fi,fi->f", new_knee - hip, normal))[ok].max() < 1e-9


def _walk(source, frames=80):
    """A clip whose hips glide forward while the left shin swings: the left ankle stays low and slow in
    the first half (a contact), so the target (other leg proportions) slides there."""
    rot = np.tile(np.eye(3), (frames, len(source.bones), 1, 1))
    t = np.linspace(0, 1, frames)
    thigh, shin = source.index["thigh.L"], source.index["shin.L"]
    rot[:, thigh] = rotvec_to_matrix(np.outer(0.25 * np.sin(2 * np.pi * t), [1, 0, 0]))
    rot[:, shin] = rotvec_to_matrix(np.outer(-0.5 * np.sin(2 * np.pi * t) ** 2, [1, 0, 0]))
    loc = np.zeros((frames, len(source.bones), 3))
    loc[:, 0] = np.outer(0.02 * np.sin(2 * np.pi * t), [0, 1, 0])
    return forward(source, local_matrices(rot, loc))


def test_planting_removes_the_sliding_of_a_retargeted_contact():
    """Target legs 30 % longer than the source's (relative to the hips' travel): the planted ankle slides
    without the clean-up and stays put with it; the root path is the same either way."""
    source, roles = humanoid(1.7)
    target, _ = humanoid(2.2)
    clip = _walk(source)
    mapping = Mapping.from_roles(roles, roles)
    off = retarget_clip(source, target, mapping, clip, RetargetOptions(fps=30.0, root_motion=False))
    on = retarget_clip(source, target, mapping, clip, RetargetOptions(fps=30.0, root_motion=False,
                                                                        foot_cleanup=True))
    report = on.report["foot_contacts"]["L"]
    assert report["contacts"] >= 1 and report["sliding_before"] > 0.01
    assert report["sliding_after"] < 0.05 * report["sliding_before"]
    assert np.allclose(on.root_locations, off.root_locations)
    loc = np.zeros(on.quaternions.shape[:2] + (3,))
    loc[:, on.root_bone] = on.root_locations
    _, heads = world_pose(target, forward(target, local_matrices(quat_to_matrix(on.quaternions), loc)))
    assert np.isfinite(heads).all()
