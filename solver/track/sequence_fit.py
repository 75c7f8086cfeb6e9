"""Pass 1 of tracking: the frames of a capture sequence fitted one after the other, each from the previous
frame's pose, without the temporal term (w_temp = 0).

Model-adaptive mocap dissertation §4.1.4 (c) and the BUFF pipeline of §4.2: "pass 1" tracks every frame
sequentially from its predecessor's result; the sliding-window pass with the temporal prior comes later
and starts from these poses.  Each frame is :func:`.frame_fit.fit_frame`.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import ArticulaInputError
from ..rig.model import Poses
from ..rig.skinning import AnchorGroups
from .frame_fit import FrameFitOptions, fit_frame


@dataclasses.dataclass
class SequenceFit:
    """Result of :func:`fit_sequence` (N frames): poses (:class:`Poses`, N frames, input order); per frame
    the :class:`.frame_fit.FrameFit` statistics (``stats``), updates (``iterations (N,)``), convergence
    (``converged (N,)``) and final Q (``energy (N,)``, m)."""
    poses: Poses
    stats: list
    iterations: np.ndarray
    converged: np.ndarray
    energy: np.ndarray


def fit_sequence(model, captures, init: Poses, prior=None, options: FrameFitOptions = FrameFitOptions(),
                 progress=None) -> SequenceFit:
    """Fit every capture of ``captures`` (a sequence of :class:`.frame_fit.Capture`) in order, frame 0
    from ``init`` (one frame) and frame n from frame n−1's result.  prior, options: as
    :func:`.frame_fit.fit_frame`; progress: optional ``progress(fraction, text)`` after each frame (may
    raise ``Cancelled``)."""
    captures = list(captures)
    if not captures:
        raise ArticulaInputError("captures: no frames to track")
    groups = AnchorGroups(model)
    pose, fits = init, []
    for n, capture in enumerate(captures):
        fit = fit_frame(model, capture, pose, prior, options, groups)
        fits.append(fit)
        pose = fit.pose
        if progress is not None:
            progress((n + 1) / len(captures), f"tracking: frame {n + 1} of {len(captures)}, "
                                              f"median {fit.stats['median_mm']:.1f} mm")
    poses = Poses(np.concatenate([f.pose.rotations for f in fits]),
                  np.concatenate([f.pose.translations for f in fits]), np.concatenate([f.pose.scales for f in fits]))
    return SequenceFit(poses, [f.stats for f in fits], np.array([f.iterations for f in fits]),
                       np.array([f.converged for f in fits]), np.array([f.log["Q"].min() for f in fits]))
