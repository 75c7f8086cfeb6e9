"""The per-frame trackers by name (``DepthTrackOptions.tracker``): each is a function
``fit(body, obs, camera, pose, options, prior=(), iterations=None) -> icp.FrameFit`` (``prior``: the
terms of :mod:`solver.tracking.priors`, the joint limits)."""
from __future__ import annotations

from . import gmm, icp


def frame_fitter(options):
    """The per-frame fit of ``options.tracker``."""
    return {"icp": icp.fit_frame, "gmm": gmm.fit_frame}[options.tracker]
