"""The inputs of a farm tracking job, checked before anything is submitted (the same checks as a
one-process ``track``, so a bad recording fails here and not on forty machines): the model bundle, the
recording and its frame count, the output paths, the chunk plan."""
from __future__ import annotations

import os

from ...solver.errors import ArticulaInputError
from ...solver.farm import chunks
from ...solver.farm.track_job import TrackJob
from ..cli.common import check_blend_output
from ..track import inputs as track_inputs
from ..track_depth import inputs as depth_inputs
from ..tracking.result import check_output_path

# kind -> (chunk size, overlap) in frames (docs/farm.md "Chunk size and overlap")
DEFAULT_CHUNK = {"depth": (300, 60), "scans": (60, 10)}


def frame_count(kind: str, folder: str, camera: str = "") -> int:
    """Frames of the recording in ``folder`` after the checks ``track`` makes (PNG depth frames with
    intrinsics.json or ``camera``; or capture files)."""
    if kind == "depth":
        return depth_inputs.recording_from_folder(folder, camera or None).total
    if kind == "scans":
        return len(track_inputs.capture_paths([folder]))
    raise ArticulaInputError(f"input kind {kind!r}: expected depth or scans")


def track_job(model: str, folder: str, kind: str, out: str, blend: str = "", chunk: int = 0, overlap: int = 0,
              options=(), camera: str = "", work_dir: str = "") -> TrackJob:
    """A checked :class:`TrackJob`; ``model`` "" with a depth recording: the built-in template body, adapted
    by a first task; ``chunk``/``overlap`` 0 take :data:`DEFAULT_CHUNK` (a chunk alone gets an overlap
    that fits: :func:`solver.farm.chunks.settings`); ``work_dir`` defaults to
    ``<out>.farm`` beside the output (on the shared storage with it)."""
    if not model and kind != "depth":
        raise ArticulaInputError("tracking captures on the farm needs the person's model bundle (--model MODEL.npz); "
                                 "only depth recordings can start from the built-in template body")
    folder, out = os.path.abspath(folder), os.path.abspath(out)
    if not out.lower().endswith(".npz"):
        raise ArticulaInputError(f"{out}: the tracked bundle must be a .npz file")
    check_output_path(out)
    check_blend_output(blend)
    if model:
        model = os.path.abspath(model)
        track_inputs.model_from_bundle(model)
    total = frame_count(kind, folder, camera)
    size, lap, _note = chunks.settings(chunk, overlap, *DEFAULT_CHUNK[kind])
    ranges = chunks.plan(total, size, lap)
    options = list(options) + (["--camera", camera] if camera and kind == "depth" else [])
    return TrackJob(model or "", folder, kind, ranges, os.path.abspath(work_dir or out + ".farm"), out,
                    os.path.abspath(blend) if blend else "", options)
