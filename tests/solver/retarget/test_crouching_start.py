"""Root motion from a clip whose first frame crouches, or jumps (solver.retarget.solve / root_motion): the
heights come from the rest pose, never from the first frame.  The target is the source scaled by 1.8, so
in every frame its hips must be exactly 1.8 times as high as the source's (both stand on z = 0)."""
import numpy as np
import pytest

from articula.solver.geometry.rotations import quat_to_matrix, rotvec_to_matrix
from articula.solver.retarget.armature import forward, local_matrices, world_pose
from articula.solver.retarget.mapping import Mapping
from articula.solver.retarget.solve import RetargetOptions, retarget_clip

from .humanoids import humanoid

SCALE = 1.8
FRAMES = 12


def _crouch_clip(arm, frames=FRAMES, deepest=1.1, lift=0.0):
    """(F, J, 4, 4): knees bent by ``deepest`` rad on frame 0, straightening to standing by the middle
    frame; the hips are lowered by exactly what the bend takes off the legs, so the flat feet stay on the
    floor, except on frame 0 when ``lift`` (m) raises the whole body (the jump's last frame in the air)."""
    bend = deepest * np.clip(1.0 - np.arange(frames) / (frames // 2), 0.0, 1.0)
    J = len(arm.bones)
    rot = np.tile(np.eye(3), (frames, J, 1, 1))
    loc = np.zeros((frames, J, 3))
    thigh = np.linalg.norm(arm.tails[arm.index["thigh.L"]] - arm.rest[arm.index["thigh.L"], :3, 3])
    for f, a in enumerate(bend):
        # world turn of each leg bone (about world X, the body's left): thigh +a, shin -a, foot 0
        turns = {"thigh": rotvec_to_matrix(np.array([a, 0, 0])), "shin": rotvec_to_matrix(np.array([-a, 0, 0])),
                 "foot": np.eye(3)}
        parent = {"thigh": np.eye(3), "shin": turns["thigh"], "foot": turns["shin"]}
        for side in "LR":
            for part in ("thigh", "shin", "foot"):
                b = arm.index[f"{part}.{side}"]
                F = arm.rest[b, :3, :3]
                rot[f, b] = F.T @ parent[part].T @ turns[part] @ F
        drop = 2 * thigh * (1 - np.cos(a))          # thigh and shin are equally long
        loc[f, 0] = arm.rest[0, :3, :3].T @ np.array([0.0, 0.0, (lift if f == 0 else 0.0) - drop])
    return forward(arm, local_matrices(rot, loc))


@pytest.mark.parametrize("lift", [0.0, 0.15])
def test_crouching_first_frame_keeps_the_true_heights(lift):
    source, roles = humanoid(1.0)
    target, _ = humanoid(SCALE)
    clip = _crouch_clip(source, lift=lift)
    _, heads_s = world_pose(source, clip)
    hips_s = heads_s[:, source.index["hips"], 2]
    assert hips_s[0] < hips_s[-1] - 0.1 + lift           # the clip starts crouched
    toes = heads_s[:, [source.index["toe.L"], source.index["toe.R"]], 2]
    np.testing.assert_allclose(toes[1:], toes[-1, 0], atol=1e-12)       # flat feet on the floor after frame 0
    np.testing.assert_allclose(toes[0], toes[-1, 0] + lift, atol=1e-12)
    result = retarget_clip(source, target, Mapping.from_roles(roles, roles), clip, RetargetOptions())
    loc = np.zeros(result.quaternions.shape[:2] + (3,))
    loc[:, result.root_bone] = result.root_locations
    _, heads_t = world_pose(target, forward(target, local_matrices(quat_to_matrix(result.quaternions), loc)))
    hips_t = heads_t[:, target.index["hips"], 2]
    np.testing.assert_allclose(hips_t, SCALE * hips_s, atol=1e-6)
