"""Fading gaze control in and out over a shot (model-adaptive mocap, Sec. 4.2.3: "the magnitude of gaze
direction adaptation is faded in and out using sigmoid functions").

The weight of frame f in a shot ``start..end`` with ``fade`` frames is 0 outside the shot, 1 from
``start + fade`` to ``end - fade``, and in between a logistic sigmoid rescaled so that it is exactly 0 at
the shot's edge and exactly 1 where full strength begins (so it is monotone and continuous).
"""
from __future__ import annotations

import numpy as np

from ..errors import ArticulaInputError

STEEPNESS = 10.0      # logistic slope over the fade (larger = closer to a step)


def sigmoid_ramp(x: np.ndarray, steepness: float = STEEPNESS) -> np.ndarray:
    """Monotone ramp from 0 at ``x <= 0`` to 1 at ``x >= 1``: the logistic ``1/(1+exp(-k(x-1/2)))``
    rescaled to hit 0 and 1 exactly at the ends."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    s = 1.0 / (1.0 + np.exp(-steepness * (x - 0.5)))
    lo, hi = 1.0 / (1.0 + np.exp(steepness / 2)), 1.0 / (1.0 + np.exp(-steepness / 2))
    return (s - lo) / (hi - lo)


def shot_weights(frames, start: int, end: int, fade: int) -> np.ndarray:
    """(F,) weights of integer ``frames`` for a shot from ``start`` to ``end`` (inclusive) with ``fade``
    frames of fade in and out."""
    if end < start:
        raise ArticulaInputError(f"gaze shot: the last frame {end} comes before the first {start}")
    if fade < 0 or 2 * fade > end - start:
        raise ArticulaInputError(f"gaze shot {start}-{end}: a fade of {fade} frames does not fit twice "
                                 f"(at most {(end - start) // 2})")
    f = np.asarray(frames, dtype=np.float64)
    if fade == 0:
        return ((f >= start) & (f <= end)).astype(np.float64)
    w = np.minimum(sigmoid_ramp((f - start) / fade), sigmoid_ramp((end - f) / fade))
    w[(f < start) | (f > end)] = 0.0
    return w
