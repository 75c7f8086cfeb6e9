"""The frames one tracking run works on: captures read on demand and one report entry per frame.

Captures are thinned to the run's ``max_points`` whatever the source was made with, and only the last
ones read are kept in memory, up to ``KEEP_BYTES`` of points and normals (at least ``KEEP_MIN`` captures,
a window's worth), so a long recording is never held whole while a short one is read once.  The next
capture can be read ahead on a thread of its own while the current one is fitted (:meth:`Recording.
prefetch`).
"""
from __future__ import annotations

import collections

from ..parallel import reader, workers
from .captures import CaptureSource
from .options import TrackOptions, frame_range

MIN_POINTS = 100        # a frame with fewer points (after cleaning) is skipped
KEEP_MIN = 24           # captures kept in memory at least ...
KEEP_BYTES = 256e6      # ... and more while their points and normals take less than this


class Recording:
    """``len(rec)`` tracked frames; ``rec.capture(i)`` the capture of tracked frame i (input frame
    ``rec.range[i]``); ``rec.entries[i]`` its report entry (a dict, filled by the stages)."""

    def __init__(self, source, options: TrackOptions):
        if isinstance(source, CaptureSource) and source.max_points != options.max_points:
            source = source.with_max_points(options.max_points)      # the options decide the thinning
        self.source = source
        self.range = frame_range(options.frames, len(source))
        self._cache = collections.OrderedDict()
        self._ahead = None                                           # (i, future) of a capture read ahead
        self.entries = [None] * len(self.range)

    def __len__(self):
        return len(self.range)

    def capture(self, i):
        if i not in self._cache:
            self._cache[i] = self._read(i)
            while len(self._cache) > KEEP_MIN and _bytes(self._cache.values()) > KEEP_BYTES:
                self._cache.popitem(last=False)
            if self.entries[i] is None:
                self.entries[i] = self._entry(i, self._cache[i])
        self._cache.move_to_end(i)
        return self._cache[i]

    def prefetch(self, i) -> None:
        """Start reading capture ``i`` on a reader thread (nothing when it is read, out of range, or the
        solver runs on one thread: :func:`solver.parallel.workers`); the next :meth:`capture` of it waits
        for that read.  A read that fails raises there."""
        if (workers() < 2 or not 0 <= i < len(self) or i in self._cache
                or (self._ahead is not None and self._ahead[0] == i)):
            return
        self._drop_ahead()
        self._ahead = (i, reader().submit(self.source.__getitem__, self.range[i]))

    def _read(self, i):
        if self._ahead is not None and self._ahead[0] == i:
            future, self._ahead = self._ahead[1], None
            return future.result()
        return self.source[self.range[i]]

    def _drop_ahead(self):
        if self._ahead is not None:
            self._ahead[1].cancel()
            self._ahead = None

    def _entry(self, i, capture):
        names = getattr(self.source, "names", None)
        info = self.source.info(self.range[i]) if hasattr(self.source, "info") else None
        return {"frame": self.range[i], "name": names[self.range[i]] if names else str(self.range[i]),
                "points": int(len(capture.points)), "dropped_nan": int(info.dropped_nan) if info else 0,
                "mean_mm": None, "median_mm": None, "mad_mm": None, "iqr_mm": None,
                "lost": False, "skipped": False, "reinitialised": False, "reason": "", "seconds": 0.0,
                "verdict": None, "checks": [], "window": None}

    def usable(self) -> list:
        """Tracked frames that were neither skipped nor lost."""
        return [i for i, e in enumerate(self.entries) if e is not None and not (e["skipped"] or e["lost"])]

    def too_few(self, i) -> bool:
        """Skip frame i (and say so in its entry) when its capture has fewer than ``MIN_POINTS``."""
        n = len(self.capture(i).points)
        if n < MIN_POINTS:
            self.entries[i].update(skipped=True, reason=f"{n} points (fewer than {MIN_POINTS})")
        return n < MIN_POINTS


def _bytes(captures) -> int:
    return sum(c.points.nbytes + c.normals.nbytes for c in captures)

