"""A chunked tracking job for a Flamenco Manager (docs/farm.md): the work (model, recording, chunk plan,
output paths) as the job of the ``articula-track`` job type (``addon/farm/job_types/articula_track.js``:
one task per chunk, named ``chunk-NNNN ...``, then a task that merges and bakes), followed by
:class:`.follow.FarmRun`."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

from ..errors import ArticulaInputError
from ..track import merge
from . import chunks as chunk_plan

JOB_TYPE = "articula-track"
KINDS = ("depth", "scans")
AGREE_MM = merge.AGREE_MM     # mm: depth chunks differing more on a cut frame started on another solution
SCANS_AGREE_MM = 1.0          # mm: capture chunks whose pass-1 poses differ more at a cut are tracked again
MAX_REPAIRS = 3               # rounds of re-tracking disagreeing chunks before the job gives up (at least)


@dataclass
class TrackJob:
    """``model``: model bundle ("" with a depth recording: a first task adapts the built-in template body on
    the first ``adapt_frames`` frames and the chunks track with it); ``input``: recording folder (``kind`` "depth" or "scans"); ``ranges``: the
    chunks' tracked ``(start, stop)``; ``work_dir``: shared folder for the chunk bundles; ``out``:
    tracked bundle; ``blend``: optional .blend to bake into; ``options``: further ``track`` flags
    (no paths); ``name``: the job's name; ``agree_mm``: the merge refuses chunks that differ more than
    this on the frame where it switches between them (0: no check; None: :data:`SCANS_AGREE_MM` for
    captures, whose chunks the repair makes equal to one run, :data:`AGREE_MM` for depth);
    ``start_from``: ``{chunk: (earlier chunk, pose index)}``, chunks to start from an earlier chunk's
    pose (``track --start-pose``); ``max_repairs``: rounds of :meth:`repair` at most (None:
    :data:`MAX_REPAIRS` or one per chunk after the first, whichever is more: a run of disagreeing chunks
    is repaired front to back); ``repairs``: rounds done; ``tracked_in``: ``{chunk: round}`` in which a
    chunk was last tracked (0, absent: the first submission).  Paths absolute, as this machine sees the
    shared storage."""
    model: str
    input: str
    kind: str
    ranges: list
    work_dir: str
    out: str
    blend: str = ""
    options: list = field(default_factory=list)
    name: str = ""
    agree_mm: float = None
    start_from: dict = field(default_factory=dict)
    adapt_frames: int = 300
    max_repairs: int = None
    repairs: int = 0
    tracked_in: dict = field(default_factory=dict)

    job_type = JOB_TYPE
    unit = "chunk"

    def __post_init__(self):
        if self.agree_mm is None:
            self.agree_mm = SCANS_AGREE_MM if self.kind == "scans" else AGREE_MM
        if self.max_repairs is None:
            self.max_repairs = max(MAX_REPAIRS, len(self.ranges) - 1)

    def chunk_path(self, k: int) -> str:
        """Where chunk ``k``'s tracked bundle lands (the output itself when there is one chunk)."""
        if len(self.ranges) == 1:
            return self.out
        return os.path.join(self.work_dir, chunk_plan.file_name(k, self.ranges[k]))

    @property
    def count(self) -> int:
        return len(self.ranges)

    @property
    def has_finish(self) -> bool:
        """Whether the job ends with a merge/bake task after the chunks."""
        return len(self.ranges) > 1 or bool(self.blend)

    def outputs_pending(self, done) -> list:
        """The tracked bundle and .blend: written by the last task, pending until the job completes."""
        return [self.out] + ([self.blend] if self.blend else [])

    @property
    def adapted_model(self) -> str:
        """Where the template adapted by the first task lands (no ``model`` given)."""
        return os.path.join(self.work_dir, "template_adapted.npz")

    def is_prep(self, task_name: str) -> bool:
        """Whether ``task_name`` is the task that adapts the template before the chunks."""
        return task_name.startswith("adapt ")

    def prep_done(self) -> None:
        """The template is adapted: later submissions track with it instead of adapting again."""
        self.model = self.adapted_model

    def unit_of(self, task_name: str):
        """Chunk number of a task named ``chunk-0003 frames A:B``, else None (the merge task)."""
        head = task_name.split(" ", 1)[0]
        if head.startswith("chunk-") and head[6:].isdigit():
            return int(head[6:])
        return None

    def prepare(self) -> None:
        """Make the folder the tasks write into (on the shared storage)."""
        try:
            os.makedirs(self.work_dir, exist_ok=True)
        except OSError as exc:
            raise ArticulaInputError(f"{self.work_dir}: cannot make the folder ({exc.strerror or exc})") from None

    def body(self, run) -> dict:
        """The job to submit, tracking the chunks ``run`` (indices) and then merging all of them."""
        if self.kind not in KINDS:
            raise ArticulaInputError(f"input kind {self.kind!r}: expected one of {', '.join(KINDS)}")
        settings = {"model": self.model, "input": self.input, "input_kind": self.kind,
                    "chunks": chunk_plan.to_text(self.ranges), "run": ",".join(str(k) for k in run) or "none",
                    "work_dir": self.work_dir, "out": self.out, "blend": self.blend or "",
                    "options": " ".join(self.options), "agree_mm": float(self.agree_mm),
                    "adapt_frames": int(self.adapt_frames),
                    "start_from": ",".join(f"{k}:{j}:{p}" for k, (j, p) in sorted(self.start_from.items()))}
        folder = os.path.basename(os.path.normpath(self.input))
        name = self.name or f"Articula track {folder}"
        return {"name": name, "type": JOB_TYPE, "settings": settings,
                "metadata": {"articula.out": self.out}}

    def repair(self, done: set) -> str:
        """After a failed merge with every chunk tracked: each cut where the later chunk started on another
        solution than the earlier one (:func:`solver.track.merge.disagreements`) gets its later chunk
        tracked again from the earlier chunk's pose at its first frame (capture tracking only: ``track
        --start-pose``), unless the earlier chunk is itself tracked again now (the next round sees its new
        pose).  Marks those chunks (removed from ``done``) and returns a line saying so; '' when no cut
        disagrees (the merge failed for another reason).  Raises :class:`ArticulaInputError` when a cut
        still disagrees after its later chunk was started from the earlier chunk as it is now, or after
        ``max_repairs`` rounds: the same merge submitted again would fail the same way."""
        if self.kind != "scans" or not self.agree_mm or len(self.ranges) < 2:
            return ""
        chunks = merge.load_chunks([self.chunk_path(k) for k in range(len(self.ranges))])
        bad = merge.disagreements(chunks, self.agree_mm)   # indices by start: the plan's order
        if not bad:
            return ""
        stuck = next((c for c in bad if not self._can_restart(*c["indices"])), None)
        if stuck is not None or self.repairs >= self.max_repairs:
            raise ArticulaInputError(self._unrepaired_text(stuck or bad[0], stuck is not None))
        self.repairs += 1
        lines = []
        for cut in bad:
            i, j = cut["indices"]
            if self.tracked_in.get(i) == self.repairs:
                continue                                   # its earlier chunk changes in this round
            self.start_from[j] = (i, self.ranges[j][0] - self.ranges[i][0])
            self.tracked_in[j] = self.repairs
            done.discard(j)
            lines.append(f"chunk {j} disagreed with chunk {i} on frame {cut['frame']} {merge.gap_text(cut)}: "
                         f"tracked again from chunk {i}'s pose")
        return "; ".join(lines)

    def _can_restart(self, i: int, j: int) -> bool:
        """Whether chunk ``j`` may be tracked again from chunk ``i``: it was not started from ``i``, or
        ``i`` was tracked again after ``j`` was."""
        return self.start_from.get(j, (None,))[0] != i or self.tracked_in.get(i, 0) > self.tracked_in.get(j, 0)

    def _unrepaired_text(self, cut: dict, stuck: bool) -> str:
        i, j = cut["indices"]
        how = (f"after it was tracked again from chunk {i}'s pose at frame {self.ranges[j][0]}" if stuck else
               f"after {self.repairs} repair round(s) (at most {self.max_repairs})")
        return (f"chunk {j} still disagrees with chunk {i} on frame {cut['frame']} {merge.gap_text(cut)} "
                f"{how}; the merge is not submitted again (it would fail the same way): give a longer --overlap, "
                f"or accept the join with --agree 0")
