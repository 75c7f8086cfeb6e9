"""One pose per tracked frame: frames that were skipped or lost get the pose interpolated between their
tracked neighbours (geodesic per bone, linear root translation and scale; held at the ends)."""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import quat_canonical, quat_conj, quat_mul, quat_normalize, quat_to_rotvec, rotvec_to_quat
from ..rig.model import Poses


def stacked(poses: dict, count: int) -> Poses:
    """``{frame: one-frame Poses}`` as ``count`` frames; frames missing hold the nearest one before
    (the first present one before it), to be replaced by :func:`interpolate_gaps`."""
    keys = sorted(poses)
    rows = [poses[max([k for k in keys if k <= i], default=keys[0])] for i in range(count)]
    return Poses(np.concatenate([p.rotations for p in rows]), np.concatenate([p.translations for p in rows]),
                 np.concatenate([p.scales for p in rows]))


def interpolate_gaps(poses, usable) -> Poses:
    """``poses`` with every frame not in ``usable`` replaced by the interpolation between the nearest
    usable frames before and after (rotations: per bone along the geodesic; translation, scale:
    linear); held at the ends."""
    out = poses.take(slice(None))
    usable = sorted(usable)
    if not usable:
        return out
    for i in range(len(poses)):
        if i in usable:
            continue
        k = np.searchsorted(usable, i)
        a = usable[max(k - 1, 0)]
        b = usable[min(k, len(usable) - 1)]
        w = 0.0 if a == b else (i - a) / (b - a)
        qa, qb = poses.rotations[a], poses.rotations[b]
        qb = np.where((np.sum(qa * qb, axis=-1) < 0)[:, None], -qb, qb)
        rel = quat_to_rotvec(quat_mul(quat_conj(qa), qb))
        out.rotations[i] = quat_canonical(quat_normalize(quat_mul(qa, rotvec_to_quat(w * rel))))
        out.translations[i] = (1 - w) * poses.translations[a] + w * poses.translations[b]
        out.scales[i] = (1 - w) * poses.scales[a] + w * poses.scales[b]
    return out
