"""Pass 1's state after every frame, kept in the tracked bundle so that a run starting at one of its
frames continues pass 1 exactly as this run went on (the farm's repair of a chunk that started on another
solution: docs/farm.md "Chunks on another solution").

Pass 1 (:mod:`.follow`) carries from frame to frame the last one or two good poses (the prediction), the
running medians (lost-frame detection), whether the last flagged frame was searched in vain, and the pose
its held Jacobian was evaluated at (:meth:`solver.tracking.body.Body.jacobian_near`: it shapes the next
frame's steps).  A chunk started from the earlier chunk's pose alone, without its velocity, took another
path within three frames on Kinect-like captures of a turn (docs/track.md "7 Dec").  :class:`Trail`
records that state per tracked frame; :meth:`Trail.arrays` gives the bundle's ``pass1_*`` arrays and
:func:`resume_at` reads one frame's state back as a :class:`Resume`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError
from ..rig.model import Poses

RUNNING = 10            # frames in the running median that lost-frame detection compares with
KEYS = ("pass1_last", "pass1_before", "pass1_held", "pass1_fitted", "pass1_medians", "pass1_in_vain")


@dataclass
class Resume:
    """Pass 1's state after one frame: ``pose`` its pass-1 pose (the last good one, so the frame's
    own), ``before`` the good pose before it (None: none), the running ``medians`` (mm, oldest first),
    ``in_vain`` (the last flagged frame was searched without a better fit), ``held`` the pose of the
    held Jacobian (None: none), ``input_frame`` (0-based number of that frame in the input) and its
    ``frame_name`` ("" unknown)."""
    pose: Poses
    before: Poses
    held: Poses
    medians: list
    in_vain: bool
    input_frame: int
    frame_name: str = ""

    @property
    def history(self) -> list:
        """The poses pass 1 predicts the next frame from (oldest first)."""
        return [self.pose] if self.before is None else [self.before, self.pose]


class Trail:
    """Pass 1's state after each of ``count`` tracked frames of a ``num_bones`` rig (NaN where a frame
    was not fitted: skipped or lost)."""

    def __init__(self, count: int, num_bones: int):
        width = 4 * num_bones + 4
        self.last = np.full((count, width), np.nan)
        self.before = np.full((count, width), np.nan)
        self.held = np.full((count, width), np.nan)
        self.fitted = np.zeros(count, bool)
        self.medians = np.full((count, RUNNING), np.nan)
        self.in_vain = np.zeros(count, bool)

    def record(self, i: int, history: list, medians: list, in_vain: bool, held: Poses = None,
               fitted: bool = True) -> None:
        """The state after tracked frame ``i``: ``history`` (one or two one-frame Poses, oldest first),
        the running ``medians``, ``held`` (the held Jacobian's pose or None); ``fitted``: the frame has a
        pass-1 pose (``history[-1]``)."""
        self.last[i] = _packed(history[-1])
        if len(history) > 1:
            self.before[i] = _packed(history[-2])
        if held is not None:
            self.held[i] = _packed(held)
        tail = list(medians)[-RUNNING:]
        self.medians[i, :len(tail)] = tail
        self.in_vain[i], self.fitted[i] = bool(in_vain), bool(fitted)

    def arrays(self) -> dict:
        """The bundle's arrays (:data:`KEYS`)."""
        return dict(zip(KEYS, (self.last, self.before, self.held, self.fitted, self.medians, self.in_vain)))


def resume_at(arrays: dict, k: int, first_frame: int, num_bones: int):
    """The :class:`Resume` of tracked frame ``k`` of a bundle whose first tracked frame is input frame
    ``first_frame`` (``arrays``: its ``pass1_*`` arrays), or None when the bundle has none or frame
    ``k`` was not fitted in pass 1.  Raises :class:`ArticulaInputError` when the arrays are malformed."""
    if not all(key in arrays for key in KEYS):
        return None
    last, before, held, fitted, medians, in_vain = (np.asarray(arrays[key]) for key in KEYS)
    width, count = 4 * num_bones + 4, len(fitted)
    shapes = {"pass1_last": (count, width), "pass1_before": (count, width), "pass1_held": (count, width),
              "pass1_medians": (count, RUNNING), "pass1_in_vain": (count,)}
    for key, shape in shapes.items():
        if np.shape(arrays[key]) != shape:
            raise ArticulaInputError(f"{key}: expected shape {shape}, got {np.shape(arrays[key])}")
    if not 0 <= k < count or not fitted[k]:
        return None
    row = medians[k]
    return Resume(_unpacked(last[k], num_bones), _unpacked(before[k], num_bones), _unpacked(held[k], num_bones),
                  [float(m) for m in row[np.isfinite(row)]], bool(in_vain[k]), int(first_frame) + int(k))


def _packed(pose: Poses) -> np.ndarray:
    """One frame's pose as one row: rotations (B x 4), translation (3), scale (1)."""
    return np.concatenate([pose.rotations[0].ravel(), pose.translations[0], pose.scales[:1]])


def _unpacked(row, num_bones: int):
    """The pose of a row of :func:`_packed`, None for a row of NaN."""
    if np.isnan(row).any():
        return None
    b4 = 4 * num_bones
    return Poses(row[:b4].reshape(1, num_bones, 4).copy(), row[b4:b4 + 3].reshape(1, 3).copy(), row[b4 + 3:].copy())
