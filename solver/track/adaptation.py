"""Model adaptation inside the scan tracker (dissertation §4.2 steps 2 and 4, "model-adaptive"): the
model's rest shape and joints refined on key frames with their poses (:func:`.adapt.adapt_model`),
then every tracked frame refitted with the adapted model from its pose; and whether the model needs it
(:func:`shape_offset`: "auto" adapts a model that is not the subject's and leaves the subject's own alone)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..rig.model import Poses
from ..tracking.body import Body
from ..tracking.frame import TRACKING, fit_frame
from ..tracking.lm import State
from ..tracking.terms import ScanToModel
from .adapt import adapt_model

MIN_KEYS = 3
SHAPE_OFF = 0.0025     # "auto" adapts a model whose surface lies further than this off the captures (m) ...
PATCH = 30             # ... averaged over patches of this many sampled capture points
OFFSET_SAMPLES = 4000  # capture points sampled per frame to measure it
OFFSET_REACH = 0.05    # pairs farther than this (m) are left out (another part's surface, not this one's shape)


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


def shape_offset(body, capture, pose, seed: int = 0) -> float:
    """How far (m) the model's surface posed by ``pose`` (one frame) lies off the ``capture`` beyond its
    noise: the median over capture patches (each sampled point's ``PATCH`` nearest sampled points) of the
    patch's mean signed capture-to-model distance along the model's normal, in absolute value.  Zero-mean
    sensor noise averages out over a patch (its standard deviation over sqrt(PATCH)); a body of another
    shape lies off to the same side over a whole patch.  Measured on the benches' fitted frames: the
    subject's own model 0.1 mm (1 mm noise) and 1.3-1.7 mm (Kinect-like captures, a learned rig included),
    a thin body's model on a heavy subject 4.5-4.8 mm (docs/track.md "Model adaptation")."""
    term = ScanToModel(capture.points, capture.normals, OFFSET_SAMPLES, reach=OFFSET_REACH, seed=seed)
    r, kept = term.residuals(State(body, pose))
    points, r = term.points[kept], r[kept]
    if len(r) < PATCH:
        return 0.0
    _, near = cKDTree(points).query(points, k=PATCH)
    return float(np.median(np.abs(r[near].mean(axis=1))))


def model_offset(body, rec, poses: dict, every: int) -> float:
    """:func:`shape_offset` (m), the median over the key frames (:func:`key_frames`) at their ``poses``."""
    keys = key_frames([i for i in rec.usable() if i in poses], every)
    offsets = [shape_offset(body, rec.capture(i), poses[i], seed=rec.range[i]) for i in keys]
    return float(np.median(offsets)) if offsets else 0.0
