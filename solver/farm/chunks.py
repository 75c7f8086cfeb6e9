"""Frame chunks of a long recording for separate tracking tasks.

Chunk ``i`` owns frames ``i*size .. (i+1)*size-1`` and tracks from ``overlap`` frames earlier, so
consecutive chunks share ``overlap`` frames; ``merge-tracks`` takes each shared frame from the chunk where
it lies furthest from a cut (:func:`solver.track.merge.choose_frames`), which leaves each side half the
overlap to settle (its first frame starts without a predecessor).  A last chunk shorter than
``overlap + 1`` owned frames is folded into the one before, so no task tracks only a handful of frames.
Ranges are ``(start, stop)``, 0-based, ``stop`` exclusive, like ``track --frames A:B``."""
from __future__ import annotations

from ..errors import ArticulaInputError

MAX_CHUNKS = 10_000


def plan(frames: int, size: int, overlap: int) -> list:
    """The tracked ``(start, stop)`` of each chunk of a ``frames``-long input (module docstring)."""
    check(frames, size, overlap)
    starts = list(range(0, frames, size))
    if len(starts) > 1 and frames - starts[-1] <= overlap:
        starts.pop()
    stops = starts[1:] + [frames]
    return [(max(0, a - overlap), b) for a, b in zip(starts, stops)]


def settings(size: int, overlap: int, default_size: int, default_overlap: int) -> tuple:
    """``(size, overlap, note)``: 0 takes the default; a chunk size given without an overlap gets
    ``min(default_overlap, size // 2)`` (at least 1) so the pair fits, and ``note`` says which ('' when
    nothing was chosen for the user)."""
    size, overlap = int(size or default_size), int(overlap)
    if overlap:
        return size, overlap, ""
    chosen = max(1, min(int(default_overlap), size // 2))
    note = f"overlap {chosen} frames (chunk {size}; give --overlap to choose)" if chosen != default_overlap else ""
    return size, chosen, note


def check(frames: int, size: int, overlap: int) -> None:
    """Raise :class:`ArticulaInputError` naming the setting when the plan cannot work."""
    if frames < 1:
        raise ArticulaInputError("the recording has no frames to track")
    if int(size) != size or size < 2:
        raise ArticulaInputError(f"chunk size: expected a whole number of frames >= 2, got {size}")
    if int(overlap) != overlap or overlap < 1:
        raise ArticulaInputError(f"overlap: expected a whole number of frames >= 1 (chunks must share frames "
                                 f"to be joined), got {overlap}")
    if overlap >= size:
        raise ArticulaInputError(f"overlap {overlap} must be smaller than the chunk size {size}")
    if frames / size > MAX_CHUNKS:
        raise ArticulaInputError(f"chunk size {size} splits {frames} frames into more than {MAX_CHUNKS} tasks; "
                                 f"use larger chunks")


def overhead(size: int, overlap: int) -> float:
    """Share of extra frames tracked because of the overlap (0.1 = 10 % more work than one run)."""
    return overlap / size


def to_text(ranges) -> str:
    """``"0:160,150:300"``: the form a job setting carries."""
    return ",".join(f"{a}:{b}" for a, b in ranges)


def from_text(text: str) -> list:
    """Inverse of :func:`to_text`; raises :class:`ArticulaInputError` on a malformed list."""
    out = []
    for item in filter(None, (t.strip() for t in str(text).split(","))):
        try:
            a, b = (int(x) for x in item.split(":"))
        except ValueError:
            raise ArticulaInputError(f"chunk {item!r}: expected START:STOP") from None
        if not 0 <= a < b:
            raise ArticulaInputError(f"chunk {item!r}: expected 0 <= START < STOP")
        out.append((a, b))
    return out


def file_name(index: int, rng) -> str:
    """File name of chunk ``index``'s tracked bundle, e.g. ``chunk_0001_0150-0300.npz``."""
    return f"chunk_{index:04d}_{rng[0]:04d}-{rng[1]:04d}.npz"
