"""Synthetic humanoid armatures for the retargeting tests: a T- or A-pose body of a given height, with
optional clavicles, hip girdles, split (twist) upper arms, fingers, random bone rolls, any bone names
and any facing; plus random clips."""
import numpy as np

from articula.sample_scenes.mpfb_rig import roll_frames
from articula.solver.geometry.rotations import rotvec_to_matrix
from articula.solver.retarget.armature import ArmatureRest, forward, local_matrices


def _joints(height, arm_angle, twist, clavicle, girdle):
    """[(role or helper name, parent, head, tail)] in metres, Z up, facing -Y (left = +X)."""
    h = height
    hips = np.array([0, 0, 0.53 * h])
    bones = [("hips", None, hips, hips + [0, 0, 0.08 * h]),
             ("spine", "hips", hips + [0, 0, 0.08 * h], hips + [0, 0, 0.2 * h]),
             ("chest", "spine", hips + [0, 0, 0.2 * h], hips + [0, 0, 0.29 * h]),
             ("neck", "chest", hips + [0, 0, 0.29 * h], hips + [0, 0, 0.35 * h]),
             ("head", "neck", hips + [0, 0, 0.35 * h], hips + [0, 0, 0.47 * h])]
    c = np.cos(np.radians(arm_angle)), np.sin(np.radians(arm_angle))
    for side, sx in (("L", 1.0), ("R", -1.0)):
        top = hips + [0, 0, 0.29 * h]
        shoulder = top + [sx * 0.11 * h, 0, -0.01 * h]
        down = np.array([sx * c[0], 0.0, -c[1]])
        elbow, wrist = shoulder + 0.186 * h * down, shoulder + 0.332 * h * down
        parent = "chest"
        if clavicle:
            bones.append((f"shoulder.{side}", "chest", top + [sx * 0.01 * h, -0.01 * h, 0], shoulder))
            parent = f"shoulder.{side}"
        if twist:
            mid = (shoulder + elbow) / 2
            bones += [(f"upper_arm.{side}", parent, shoulder, mid), (f"upper_twist.{side}", f"upper_arm.{side}", mid, elbow)]
            parent = f"upper_twist.{side}"
        else:
            bones.append((f"upper_arm.{side}", parent, shoulder, elbow))
            parent = f"upper_arm.{side}"
        bones += [(f"forearm.{side}", parent, elbow, wrist),
                  (f"hand.{side}", f"forearm.{side}", wrist, wrist + 0.1 * h * down)]
        hip = hips + [sx * 0.05 * h, 0, -0.02 * h]
        knee, ankle = hip - [0, 0, 0.245 * h], hip - [0, 0, 0.49 * h]
        parent = "hips"
        if girdle:
            bones.append((f"hip.{side}", "hips", hips, hip))
            parent = f"hip.{side}"
        bones += [(f"thigh.{side}", parent, hip, knee), (f"shin.{side}", f"thigh.{side}", knee, ankle),
                  (f"foot.{side}", f"shin.{side}", ankle, ankle + [0, -0.1 * h, -0.03 * h]),
                  (f"toe.{side}", f"foot.{side}", ankle + [0, -0.1 * h, -0.03 * h], ankle + [0, -0.15 * h, -0.03 * h])]
    return bones


def humanoid(height=1.7, arm_angle=0.0, twist=False, clavicle=True, girdle=False, rng=None, names=None,
             yaw_deg=0.0, world_scale=1.0, offset=(0, 0, 0), name="rig"):
    """``(ArmatureRest, {role: bone name})``: ``arm_angle`` 0 = T-pose, 45 = A-pose; ``rng`` rolls the
    bones randomly; ``names(role) -> bone name`` renames; ``yaw_deg`` turns the object about Z."""
    spec = _joints(height, arm_angle, twist, clavicle, girdle)
    roles = [s[0] for s in spec]
    index = {r: i for i, r in enumerate(roles)}
    heads, tails = np.array([s[2] for s in spec], float), np.array([s[3] for s in spec], float)
    rolls = rng.uniform(-np.pi, np.pi, len(spec)) if rng is not None else np.zeros(len(spec))
    frames = roll_frames(heads, tails, rolls)
    rest = np.tile(np.eye(4), (len(spec), 1, 1))
    rest[:, :3, :3], rest[:, :3, 3] = frames, heads
    parents = np.array([index[s[1]] if s[1] else -1 for s in spec])
    connected = np.array([p >= 0 and np.allclose(heads[b], tails[p]) for b, p in enumerate(parents)])
    world = np.eye(4)
    world[:3, :3] = world_scale * rotvec_to_matrix(np.array([0, 0, np.radians(yaw_deg)]))
    world[:3, 3] = offset
    bone_names = [names(r) if names else r for r in roles]
    arm = ArmatureRest(name, bone_names, parents, rest, tails, connected, world)
    return arm, {r: n for r, n in zip(roles, bone_names) if "twist" not in r}


def random_clip(arm, frames=20, amplitude=0.6, seed=0, travel=(0.0, -1.0, 0.0)):
    """(F, J, 4, 4) armature-space pose matrices: random bone rotations, the root walking along ``travel``
    (armature units over the clip) with a vertical bob."""
    rng = np.random.default_rng(seed)
    rot = rotvec_to_matrix(rng.normal(0.0, amplitude / 2, (frames, len(arm.bones), 3)))
    loc = np.zeros((frames, len(arm.bones), 3))
    t = np.linspace(0.0, 1.0, frames)
    root_axes = arm.rest[0, :3, :3]
    loc[:, 0] = (np.outer(t, travel) + np.outer(0.03 * np.sin(8 * t), [0, 0, 1])) @ root_axes
    return forward(arm, local_matrices(rot, loc))
