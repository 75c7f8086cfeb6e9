"""Root motion of a retargeted clip: where the target's hips go, and the root bone location that puts
them there.

The source's hips displacement is scaled by the leg-length ratio ``k = target legs / source legs``
(thigh + shin, world units), so stride and hip bob keep their proportion to the body and unit
differences cancel.  Vertically the displacement is taken from the source's rest hips height (a standing
rest pose on both rigs); horizontally from the source's first frame, so the target starts where it stands.
*In place* removes the travel but keeps the sway: the horizontal displacement minus its centred moving
average over about a second.
"""
from __future__ import annotations

import numpy as np

from ..errors import ArticulaInputError
from .armature import ArmatureRest, forward, local_matrices, rest_world
from .roles import LEG_ROLES


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


def hips_path(src_hips: np.ndarray, src_rest_hips: np.ndarray, tgt_rest_hips: np.ndarray, ratio: float,
              in_place: bool = False, fps: float = 24.0) -> np.ndarray:
    """(F, 3) world positions of the target's hips from the source's ``src_hips (F, 3)`` (Z up)."""
    d = np.empty_like(src_hips)
    d[:, 2] = src_hips[:, 2] - src_rest_hips[2]
    d[:, :2] = src_hips[:, :2] - src_hips[0, :2]
    if in_place:
        d[:, :2] -= moving_average(d[:, :2], round(fps))
    return tgt_rest_hips + ratio * d


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
