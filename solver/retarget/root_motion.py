"""Root motion of a retargeted clip: where the target's hips go, and the root bone location that puts
them there.

The source's hips displacement is scaled by the leg-length ratio ``k = target legs / source legs``
(thigh + shin, world units), so stride and sway keep their proportion to the body and unit differences
cancel; horizontally it is taken from the source's first frame, so the target starts where it stands.
*In place* removes the travel but keeps the sway: the horizontal displacement minus its centred moving
average over about a second.  Vertically the feet decide: in every frame the target's lowest foot point
(heads and tails of the feet and toes) is ``k`` times as high above its ground as the source's is above
its own (:func:`source_ground`, :func:`target_ground`: the rest pose's lowest foot point, or the object's
origin for skeletons that hang from it), so feet meet the ground together whatever the rigs' rest poses,
proportions and object transforms.  World up is +Z.
"""
from __future__ import annotations

import numpy as np

from ..errors import ArticulaInputError
from .armature import ArmatureRest, forward, local_matrices, rest_world
from ..roles import LEG_ROLES

FOOT_ROLES = ("foot.L", "foot.R", "toe.L", "toe.R")
GROUND_PERCENTILE = 5     # where the clip's feet come down: this percentile of the lowest foot point's height
HANG = 0.1                # rest feet this far (leg lengths) from the object's origin may not stand on it


def leg_length(arm: ArmatureRest, roles: dict) -> float:
    """Mean over the sides of thigh + shin rest length (world units); ``roles`` = ``{role: bone}``."""
    _, h = rest_world(arm)
    lengths = []
    for thigh, shin, foot in LEG_ROLES.values():
        if all(r in roles for r in (thigh, shin, foot)):
            a, b, c = (h[arm.index[roles[r]]] for r in (thigh, shin, foot))
            lengths.append(np.linalg.norm(b - a) + np.linalg.norm(c - b))
    if not lengths or max(lengths) <= 0:
        raise ArticulaInputError(f"armature {arm.name!r}: no thigh, shin and foot to measure the legs "
                                 "(needed to scale the root motion)")
    return float(np.mean(lengths))


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average of ``x (F, ...)`` along axis 0 over ``window`` frames (edges replicated)."""
    window = max(1, min(int(window) | 1, 2 * (len(x) // 2) + 1))
    half = window // 2
    padded = np.concatenate([np.repeat(x[:1], half, 0), x, np.repeat(x[-1:], half, 0)])
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), padded]), axis=0)
    return (c[window:] - c[:-window]) / window


def hips_path(src_hips: np.ndarray, tgt_rest_hips: np.ndarray, heights: np.ndarray, ratio: float,
              in_place: bool = False, fps: float = 24.0) -> np.ndarray:
    """(F, 3) world positions of the target's hips: horizontally the source's ``src_hips (F, 3)`` moved
    from its first frame times ``ratio``, vertically ``heights (F,)`` (:func:`hips_heights`)."""
    d = ratio * (src_hips[:, :2] - src_hips[0, :2])
    if in_place:
        d -= moving_average(d, round(fps))
    return np.concatenate([tgt_rest_hips[:2] + d, heights[:, None]], axis=1)


def foot_points(arm: ArmatureRest, pose: np.ndarray, bones) -> np.ndarray:
    """(F, 2B, 3) world heads and tails of ``bones`` (B indices) under armature-space ``pose (F, J, 4, 4)``."""
    bones = list(bones)
    tails = np.concatenate([arm.tails[bones], np.ones((len(bones), 1))], axis=1)
    local_tails = np.einsum("bij,bj->bi", np.linalg.inv(arm.rest[bones]), tails)
    posed_tails = np.einsum("fbij,bj->fbi", pose[:, bones], local_tails)[..., :3]
    return arm.world_points(np.concatenate([pose[:, bones][..., :3, 3], posed_tails], axis=1))


def source_ground(rest_low: float, origin: float, clip_low: np.ndarray, leg: float) -> float:
    """World height the source's feet stand on: its rest pose's lowest foot point ``rest_low``, unless that
    hangs well away (over ``HANG`` leg lengths ``leg``) from the object's origin height ``origin`` and the
    clip's feet (``clip_low (F,)``, lowest foot point per frame) come down nearer to the origin: then the
    origin (a skeleton that hangs from its root at the origin, as a BVH whose root offset is zero: its
    root channels are positions over the file's floor)."""
    down = float(np.percentile(clip_low, GROUND_PERCENTILE))
    if abs(rest_low - origin) > HANG * leg and abs(down - origin) < abs(down - rest_low):
        return float(origin)
    return float(rest_low)


def target_ground(rest_low: float, origin: float, leg: float) -> float:
    """World height the target stands on: its rest pose's lowest foot point ``rest_low``, unless that is
    over ``HANG`` leg lengths ``leg`` above the object's origin height ``origin`` (a rest pose that does
    not stand, as a learned rig's rest scan with a leg raised): then the origin."""
    return float(origin) if rest_low - origin > HANG * leg else float(rest_low)


def hips_heights(source: ArmatureRest, target: ArmatureRest, pairs: dict, source_pose: np.ndarray,
                 target_local: np.ndarray, ratio: float) -> np.ndarray:
    """(F,) world heights of the target's hips head that put its lowest foot point ``ratio`` times as high
    above its ground as the source's above its own; ``pairs`` = ``{role: (source, target bone)}``,
    ``source_pose (F, Js, 4, 4)`` armature space, ``target_local (F, Jt, 3, 3)`` pose-bone rotations."""
    roles = [r for r in FOOT_ROLES if r in pairs]
    feet_s = [source.index[pairs[r][0]] for r in roles]
    feet_t = [target.index[pairs[r][1]] for r in roles]
    src_low = foot_points(source, source_pose, feet_s)[..., 2].min(axis=1)
    ground = source_ground(foot_points(source, source.rest[None], feet_s)[0, :, 2].min(), source.world[2, 3],
                           src_low, leg_length(source, {r: s for r, (s, _) in pairs.items()}))
    floor = target_ground(foot_points(target, target.rest[None], feet_t)[0, :, 2].min(), target.world[2, 3],
                          leg_length(target, {r: t for r, (_, t) in pairs.items()}))
    pose = forward(target, local_matrices(target_local))
    hips = target.world_points(pose[:, target.index[pairs["hips"][1]], :3, 3])
    below_hips = foot_points(target, pose, feet_t)[..., 2].min(axis=1) - hips[:, 2]
    return floor + ratio * (src_low - ground) - below_hips


def root_locations(target: ArmatureRest, local_rot: np.ndarray, hips: int, bone: int, want: np.ndarray):
    """(F, 3) pose location of bone ``bone`` (the hips or its first unconnected ancestor) that puts the
    head of bone ``hips`` at world points ``want (F, 3)``, with pose rotations ``local_rot (F, J, 3, 3)``."""
    pose = forward(target, local_matrices(local_rot))
    have = pose[:, hips, :3, 3]
    p = target.parents[bone]
    base = target.relative_rest()[bone][None] if p < 0 else pose[:, p] @ target.relative_rest()[bone]
    A = base[:, :3, :3]
    return np.einsum("fji,fj->fi", A, target.armature_points(want) - have)


def translation_bone(target: ArmatureRest, hips: int, mapped=()) -> int:
    """The bone whose location moves the whole body: the hips, or its nearest ancestor that carries every
    ``mapped`` bone (a learned rig whose root part is the chest), then up past connected bones."""
    b = hips
    while target.parents[b] >= 0 and (not all(target.is_ancestor(b, m) for m in mapped) or target.connected[b]):
        b = target.parents[b]
    return b
