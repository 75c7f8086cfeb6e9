"""The tracked poses smoothed over time once every frame is tracked (ours; a centred 3-tap filter,
weights 1/4 1/2 1/4, on the joints' local rotations and the root translation): the per-frame fits
jitter with the sensor noise, and a centred filter removes jitter without the lag a causal one adds.
Runs of frames are smoothed separately: a re-initialised, lost or empty frame starts a new run (a doubtful
one, tracked from the frame before, continues it),
and a frame whose joints jump from a neighbour by more than ``JUMP_DEG`` (or its root by ``JUMP_M``) is
kept as fitted: the filter is for sensor jitter, and averaging two different poses gives neither."""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import quat_normalize
from ..rig.model import Poses

WEIGHTS = np.array([0.25, 0.5, 0.25])
FOLLOWED = ("tracked", "limbs searched", "initialised", "doubtful")   # a pose the next frame follows from
JUMP_DEG = 30.0   # a joint turning more than this between neighbouring frames is a jump, not jitter
JUMP_M = 0.15     # the root moving more than this between neighbouring frames is a jump


def _jumps(nb: np.ndarray, trans: np.ndarray) -> bool:
    """Whether the three frames' local rotations ``nb`` (3, B, 4), sign-aligned, or root translations
    ``trans`` (3, 3) jump between neighbours."""
    cos_half = np.abs((nb[1:] * nb[:-1]).sum(axis=-1)).min()
    return bool(cos_half < np.cos(np.radians(JUMP_DEG) / 2)) or bool(np.linalg.norm(np.diff(trans, axis=0),
                                                                                     axis=1).max() > JUMP_M)


def runs(statuses) -> list:
    """``(start, stop)`` of the runs of consecutive frames tracked from their predecessor."""
    out, start = [], None
    for k, s in enumerate(list(statuses) + ["end"]):
        cont = s in FOLLOWED and s != "initialised"
        if start is not None and not cont:
            out.append((start, k))
            start = None
        if s in FOLLOWED and start is None:
            start = k
    return out


def smooth(poses: Poses, statuses) -> Poses:
    """``poses`` (N frames) with every inner frame of each run replaced by the weighted mean of itself
    and its neighbours (quaternions sign-aligned to the middle one, then normalised)."""
    rot, trans = poses.rotations.copy(), poses.translations.copy()
    for a, b in runs(statuses):
        for k in range(a + 1, b - 1):
            nb = poses.rotations[k - 1:k + 2].copy()
            nb *= np.where((nb * poses.rotations[k]).sum(axis=-1, keepdims=True) < 0, -1.0, 1.0)
            if _jumps(nb, poses.translations[k - 1:k + 2]):
                continue
            rot[k] = quat_normalize(np.einsum("f,fbq->bq", WEIGHTS, nb))
            trans[k] = WEIGHTS @ poses.translations[k - 1:k + 2]
    return Poses(rot, trans, poses.scales.copy())
