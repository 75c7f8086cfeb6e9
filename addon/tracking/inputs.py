"""What both trackers read the same way: the model to track with (:class:`ModelInput`), a frame range
given as text (:func:`parse_frames`), and the ID properties that mark a tracked action and a rig's
training action."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.rig.model import Model, Poses

TRACKED_ACTION = "articula_tracked"        # action ID property: made by tracking (not training poses)
TRAINING_ACTION = "articula_training_action"   # rig ID property: the action its training poses came from


@dataclass
class ModelInput:
    """The model to track with, the poses it was trained on (None: none, the generic prior is used),
    how messages name it, its digest (``solver.tracking.provenance.model_digest``), the rig it came from
    ("" for a file) and optionally the pose the first tracked frame starts from."""
    model: Model
    training_poses: Poses = None
    label: str = ""
    sha256: str = ""
    rig: str = ""
    matrix: np.ndarray = None         # (4, 4) solve frame -> world; None: chosen by the captures
    training_action: str = ""
    start_pose: Poses = None          # the first frame's start (one frame); None: found automatically
    start_label: str = ""             # where start_pose came from (the report's input.start)
    resume: object = None             # pass 1's state of another run at start_pose (solver.track.trail.Resume)


def parse_frames(text: str, count: int, flag: str = "--frames"):
    """``(a, b)`` input frames a..b-1 (0-based, b exclusive) of "A:B", "A:" or ":B"; raises naming ``flag``
    when malformed or outside the ``count`` frames of the input."""
    parts = str(text).split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a = int(parts[0]) if parts[0].strip() else 0
        b = int(parts[1]) if parts[1].strip() else count
    except ValueError:
        raise ArticulaInputError(f"{flag}: expected A:B (first input frame, from 0, and the frame after the last), "
                                 f"got {text!r}") from None
    if not 0 <= a < b:
        raise ArticulaInputError(f"{flag} {text}: expected 0 <= A < B")
    if b > count:
        raise ArticulaInputError(f"{flag} {text}: the input has {count} frames (0..{count - 1}), so B is at most "
                                 f"{count}")
    return a, b
