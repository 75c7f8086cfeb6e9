"""Model adaptation inside the scan tracker (dissertation §4.2 steps 2 and 4, "model-adaptive"): the
model's rest shape and joints refined on key frames with their poses (:func:`.adapt.adapt_model`),
then every tracked frame refitted with the adapted model from its pose."""
from __future__ import annotations

import numpy as np

from ..rig.model import Poses
from ..tracking.body import Body
from ..tracking.frame import TRACKING, fit_frame
from .adapt import adapt_model

MIN_KEYS = 3


def key_frames(usable, every: int) -> list:
    """Every ``every``-th usable frame, at least ``MIN_KEYS`` spread over the range when there are."""
    keys = usable[::every]
    if len(keys) < MIN_KEYS:
        keys = [usable[k] for k in np.unique(np.linspace(0, len(usable) - 1, min(MIN_KEYS, len(usable))).astype(int))]
    return keys


def adapt_on_keys(body, rec, poses: dict, prior, training_poses, options, settings, say):
    """``(adapted Body, {frame: pose})``: the model adapted on the key frames, every frame refitted."""
    usable = [i for i in rec.usable() if i in poses]
    keys = key_frames(usable, options.adapt_every)
    key_poses = Poses(np.concatenate([poses[i].rotations for i in keys]),
                      np.concatenate([poses[i].translations for i in keys]),
                      np.concatenate([poses[i].scales for i in keys]))
    report = lambda f, text: say(0.6 + 0.1 * f, f"adapting the model: {text}")
    out = adapt_model(body.model, [rec.capture(i) for i in keys], key_poses, prior, progress=report,
                      training_poses=training_poses)
    adapted = Body(out.model)
    refit = {}
    for i in sorted(poses):
        c = rec.capture(i)
        refit[i] = fit_frame(adapted, c.points, c.normals, poses[i], settings=settings, stages=TRACKING,
                             seed=rec.range[i]).pose
    return adapted, refit
