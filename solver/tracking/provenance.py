"""The provenance of a tracked bundle, written by both trackers and read by ``merge-tracks``
(:mod:`solver.track.merge`): ``source`` "track", ``model_sha256`` (:func:`model_digest` of the model the
run started from), ``input`` (name and frame count of the input), ``first_frame`` (index of the first
tracked frame in the input, 0-based), ``frame_names`` (one per tracked frame), ``options`` (the tracking
options, without the frame range), ``adapted`` and, optionally, ``report``."""
from __future__ import annotations

import hashlib

import numpy as np

from ..rig.model import Model

SOURCE = "track"          # provenance "source" of every tracked bundle


def model_digest(model: Model) -> str:
    """SHA-256 (hex) of the model's arrays as a bundle stores them (rest vertices and frames float64,
    weights float32, bone names): the same model saved twice has the same digest."""
    sk = model.skeleton
    h = hashlib.sha256()
    for a in (np.asarray(model.rest_vertices, np.float64), np.asarray(model.faces, np.int32),
              np.asarray(sk.parents, np.int32), np.asarray(sk.heads, np.float64), np.asarray(sk.tails, np.float64),
              np.asarray(sk.frames, np.float64), np.asarray(model.anchor, np.int32),
              np.asarray(model.twist_weights, np.float32), np.asarray(model.swing_weights, np.float32)):
        h.update(str(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    h.update("\0".join(sk.names).encode())
    return h.hexdigest()


def track_provenance(model_sha256: str, source: str, input_frames: int, first_frame: int, frame_names,
                     options: dict, adapted: bool, report: dict = None) -> dict:
    """The provenance of a tracked bundle (module docstring); ``options`` must be JSON-serialisable."""
    prov = {"source": SOURCE, "model_sha256": str(model_sha256),
            "input": {"source": str(source), "frames": int(input_frames)},
            "first_frame": int(first_frame), "frame_names": [str(n) for n in frame_names],
            "options": {k: v for k, v in dict(options).items() if k != "frames"}, "adapted": bool(adapted)}
    if report is not None:
        prov["report"] = report
    return prov
