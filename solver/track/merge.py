"""Joining tracked chunks: a long recording tracked in pieces (``track --frames A:B``, with a few frames of
overlap between consecutive pieces) becomes one tracked bundle with one pose per frame.

A tracked bundle ("articula-model/1", written by ``track``) carries in its provenance what a merge checks
(:mod:`solver.tracking.provenance`: the model's digest, the input, the first frame, the frame names, the
options, whether the model was adapted).

Chunks belong together when they share the model digest, bone names, vertex count, input and options.
Each frame covered by several chunks is taken from the chunk where it lies furthest from a cut (a chunk
boundary inside the merged range): near a cut a chunk has tracked only a few frames on that side (its first
frame starts without a predecessor), further in it has the same temporal context as one run would.  Ties
go to the earlier chunk.  A capture tracker's chunk reports per frame the window of the temporal pass it
took its pose from (:mod:`solver.tracking.window`); a frame is taken from a chunk whose window for it is
the one a single run over the merged range would use, when one is: there the chunk's pose is the single
run's whenever its pass 1 was (a chunk resumed from the earlier one's state: :mod:`.trail`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import ArticulaInputError
from ..formats.bundle import load_bundle
from ..rig.model import Model, Poses
from ..rig.skinning import hybrid_skin
from ..tracking.provenance import SOURCE, track_provenance
from ..tracking.window import owner, schedule
from .trail import KEYS as TRAIL_KEYS
from .trail import resume_at

#: mm: chunks whose posed vertices differ more at a cut started on another solution (``merge-tracks`` and
#: the farm refuse such a join by default; docs/farm.md).
AGREE_MM = 100.0
REQUIRED = ("model_sha256", "input", "first_frame", "frame_names", "options", "adapted")


@dataclass
class TrackChunk:
    """One tracked bundle: its ``name`` (file name, for messages), model, poses (one per tracked frame)
    and tracking provenance."""
    name: str
    model: Model
    poses: Poses
    provenance: dict
    pass1: dict = None          # pass 1's state per frame (:mod:`.trail`), when the bundle has it

    def pass1_pose(self, frame: int):
        """The pass-1 pose of input ``frame`` (one frame), or None (no record, or not fitted in pass 1)."""
        if not self.pass1:
            return None
        resume = resume_at(self.pass1, frame - self.start, self.start, self.model.skeleton.num_bones)
        return None if resume is None else resume.pose

    @property
    def start(self) -> int:
        return int(self.provenance["first_frame"])

    @property
    def end(self) -> int:
        """One past the last tracked frame (input index)."""
        return self.start + len(self.poses)


def chunk_from_bundle(bundle, name: str) -> TrackChunk:
    """A :class:`TrackChunk` of a loaded bundle; raises unless it is a tracked bundle with one pose per
    tracked frame."""
    prov = bundle.provenance or {}
    missing = [k for k in REQUIRED if k not in prov]
    if prov.get("source") != SOURCE or missing:
        raise ArticulaInputError(f"{name}: not a tracked bundle (its provenance has no tracking record"
                                 f"{', e.g. ' + repr(missing[0]) if missing else ''}); make chunks with "
                                 f"`track --frames A:B`")
    if bundle.poses is None or len(bundle.poses) == 0:
        raise ArticulaInputError(f"{name}: the tracked bundle holds no poses")
    if len(prov["frame_names"]) != len(bundle.poses):
        raise ArticulaInputError(f"{name}: {len(bundle.poses)} poses but {len(prov['frame_names'])} frame names")
    first, total = prov["first_frame"], prov["input"].get("frames")
    if not isinstance(first, int) or not isinstance(total, int) or first < 0 or first + len(bundle.poses) > total:
        raise ArticulaInputError(f"{name}: frames {first}..{first}+{len(bundle.poses)} do not fit an input of "
                                 f"{total} frames")
    pass1 = {k: bundle.extra[k] for k in TRAIL_KEYS if k in bundle.extra} or None
    return TrackChunk(name, bundle.model, bundle.poses, prov, pass1)


def load_chunks(paths) -> list:
    """The tracked bundles at ``paths`` as :class:`TrackChunk` (named by their file names)."""
    return [chunk_from_bundle(load_bundle(p), os.path.basename(p)) for p in paths]


@dataclass
class MergedTrack:
    """Result of :func:`merge_chunks`: the model (of the chunk giving most frames when the chunks were
    adapted separately), one pose per frame of the merged range, its provenance and the merge report."""
    model: Model
    poses: Poses
    provenance: dict
    report: dict = field(default_factory=dict)


def choose_frames(ranges, lo: int, hi: int) -> np.ndarray:
    """Chunk index per frame ``lo..hi-1`` for chunks covering ``ranges`` [(start, end)]: the covering
    chunk whose nearest cut (a boundary strictly inside ``lo..hi``) is furthest; ties: the earlier
    chunk."""
    f = np.arange(lo, hi)
    best, score = np.full(len(f), -1), np.full(len(f), -np.inf)
    for i, (a, b) in enumerate(ranges):
        inside = (f >= a) & (f < b)
        d = np.full(len(f), np.inf)
        if a > lo:
            d = np.minimum(d, f - a)
        if b < hi:
            d = np.minimum(d, b - 1 - f)
        better = inside & (d > score)
        best[better], score[better] = i, d[better]
    return best


def choose_frames_causal(ranges, lo: int, hi: int, look_ahead: int) -> np.ndarray:
    """Chunk index per frame ``lo..hi-1`` for causal chunks sorted by start: a frame comes from the
    earliest chunk covering it unless it is among that chunk's last ``look_ahead`` frames before the
    next chunk's range (then from the next chunk)."""
    f = np.arange(lo, hi)
    best = np.full(len(f), -1)
    for i, (a, b) in reversed(list(enumerate(ranges))):
        last = i == len(ranges) - 1
        usable = (f >= a) & (f < (b if last else max(b - look_ahead, ranges[i + 1][0])))
        best[usable] = i
    return best


def _look_ahead(chunks):
    """The chunks' common ``look_ahead`` (causal trackers), else None."""
    values = {c.provenance.get("look_ahead") for c in chunks}
    value = values.pop() if len(values) == 1 else None
    return value if isinstance(value, int) and value >= 0 else None


def _check_compatible(chunks) -> None:
    """Raise unless every chunk was tracked from the same model, input and options as the first."""
    ref = chunks[0]
    for c in chunks[1:]:
        pair = f"{ref.name} and {c.name}"
        if c.provenance["model_sha256"] != ref.provenance["model_sha256"]:
            raise ArticulaInputError(f"{pair} were tracked with different models (model hashes "
                                     f"{ref.provenance['model_sha256'][:12]} and {c.provenance['model_sha256'][:12]})")
        if list(c.model.skeleton.names) != list(ref.model.skeleton.names):
            raise ArticulaInputError(f"{pair} have different bones")
        if c.model.num_vertices != ref.model.num_vertices:
            raise ArticulaInputError(f"{pair} have different vertex counts ({ref.model.num_vertices} and "
                                     f"{c.model.num_vertices})")
        if c.provenance["input"] != ref.provenance["input"]:
            raise ArticulaInputError(f"{pair} come from different inputs ({ref.provenance['input']} and "
                                     f"{c.provenance['input']})")
        if c.provenance["options"] != ref.provenance["options"]:
            diff = sorted(k for k in set(c.provenance["options"]) | set(ref.provenance["options"])
                          if c.provenance["options"].get(k) != ref.provenance["options"].get(k))
            raise ArticulaInputError(f"{pair} were tracked with different options ({', '.join(diff)})")
        if c.provenance["adapted"] != ref.provenance["adapted"]:
            raise ArticulaInputError(f"{pair}: one was tracked with model adaptation and one without")


def _check_coverage(chunks) -> None:
    """Raise unless the chunks (sorted by start) overlap pairwise in order, none inside another, and
    agree on the names of the frames they share."""
    for prev, c in zip(chunks, chunks[1:]):
        pair = f"{prev.name} (frames {prev.start}:{prev.end}) and {c.name} (frames {c.start}:{c.end})"
        if c.start <= prev.start or c.end <= prev.end:
            raise ArticulaInputError(f"{pair}: one chunk lies inside the other; give chunks that each add frames")
        if c.start > prev.end:
            raise ArticulaInputError(f"{pair}: frames {prev.end}:{c.start} are missing between them")
        if c.start == prev.end:
            raise ArticulaInputError(f"{pair} do not overlap; track chunks with a few frames in common (e.g. "
                                     f"--frames {max(c.start - 5, 0)}:{c.end}) so the joined poses agree")
        ours = prev.provenance["frame_names"][c.start - prev.start:]
        theirs = c.provenance["frame_names"][:prev.end - c.start]
        bad = next((k for k, (x, y) in enumerate(zip(ours, theirs)) if x != y), None)
        if bad is not None:
            raise ArticulaInputError(f"{pair}: input frame {c.start + bad} is {ours[bad]!r} in one and "
                                     f"{theirs[bad]!r} in the other")


def _overlap_differences(prev: TrackChunk, c: TrackChunk) -> dict:
    """Largest pose differences of two chunks on their shared frames: bone rotation (degrees) and
    root translation (mm)."""
    a, b = slice(c.start - prev.start, None), slice(0, prev.end - c.start)
    dot = np.abs(np.einsum("fbi,fbi->fb", prev.poses.rotations[a], c.poses.rotations[b]))
    angle = np.degrees(2 * np.arccos(np.clip(dot, 0.0, 1.0)))
    move = 1000 * np.linalg.norm(prev.poses.translations[a] - c.poses.translations[b], axis=1)
    return {"chunks": [prev.name, c.name], "frames": [c.start, prev.end],
            "max_rotation_deg": float(angle.max()), "max_translation_mm": float(move.max())}


def _merged_frame_rows(chunks, chosen, lo) -> list:
    """The per-frame rows of the chunks' reports (``report["frames"]``) for the frames they give, or []
    when a chunk has no such rows."""
    rows = []
    for k, i in enumerate(chosen):
        own = (chunks[i].provenance.get("report") or {}).get("frames")
        if not isinstance(own, list) or len(own) != len(chunks[i].poses):
            return []
        rows.append(own[lo + k - chunks[i].start])
    return rows


def cut_differences(chunks, chosen, lo: int) -> list:
    """At each cut (the first frame the merge takes from the next chunk) the largest distance (mm) between
    the two chunks' posed vertices on that frame (``max_vertex_mm``): a few mm when both settled on the
    same motion, far more when one started on another solution of an ambiguous first frame; and, when
    both chunks carry pass 1's record, the same between their pass-1 poses (``pass1_mm``: 0 for a chunk
    resumed from the other, :mod:`.trail`).  ``chunks`` sorted by start."""
    out = []
    for k in range(1, len(chosen)):
        i, j, f = int(chosen[k - 1]), int(chosen[k]), lo + k
        if i == j:
            continue
        a, b = chunks[i], chunks[j]
        if not (a.start <= f < a.end and b.start <= f < b.end):
            continue
        va = hybrid_skin(a.model, a.poses.take(f - a.start))[0]
        vb = hybrid_skin(b.model, b.poses.take(f - b.start))[0]
        cut = {"chunks": [a.name, b.name], "indices": [i, j], "frame": f,
               "max_vertex_mm": 1000 * float(np.linalg.norm(va - vb, axis=1).max())}
        pa, pb = a.pass1_pose(f), b.pass1_pose(f)
        if pa is not None and pb is not None:
            pa, pb = hybrid_skin(a.model, pa)[0], hybrid_skin(b.model, pb)[0]
            cut["pass1_mm"] = 1000 * float(np.linalg.norm(pa - pb, axis=1).max())
        out.append(cut)
    return out


def differs(cut: dict, agree_mm: float) -> bool:
    """Whether the chunks of ``cut`` started on different solutions: their pass-1 poses (else their poses)
    differ there by more than ``agree_mm`` (mm; None or 0: never)."""
    return bool(agree_mm) and cut.get("pass1_mm", cut["max_vertex_mm"]) > agree_mm


def gap_text(cut: dict) -> str:
    """How far the chunks of ``cut`` differ, as :func:`differs` judges it ("by 12 mm in pass 1")."""
    if "pass1_mm" in cut:
        return f"by {cut['pass1_mm']:.1f} mm in pass 1"
    return f"by {cut['max_vertex_mm']:.0f} mm"


def _choose(chunks) -> np.ndarray:
    """Chunk index per merged frame of ``chunks`` sorted by start (the causal rule when they have
    ``look_ahead``, else the symmetric one)."""
    lo, hi = chunks[0].start, chunks[-1].end
    ranges, look_ahead = [(c.start, c.end) for c in chunks], _look_ahead(chunks)
    if look_ahead is None:
        return same_windows(chunks, choose_frames(ranges, lo, hi), lo, hi)
    return choose_frames_causal(ranges, lo, hi, look_ahead)


def same_windows(chunks, chosen, lo: int, hi: int) -> np.ndarray:
    """``chosen`` (chunk index per frame ``lo..hi-1``) with each frame moved to a chunk whose temporal
    window for it (its report's ``window``) is the one a single run over ``lo..hi`` would use (its
    options' ``window`` and ``step``), when the chosen chunk's is not and another's is."""
    options = chunks[0].provenance.get("options") or {}
    size, step = options.get("window"), options.get("step")
    if not isinstance(size, int) or not isinstance(step, int) or not options.get("temporal", True):
        return chosen
    n = hi - lo
    windows = schedule(list(range(n)), list(range(lo, hi)), size, step)
    target = [[lo + windows[w][0], lo + windows[w][-1]] for w in owner(windows, n)]
    out = np.array(chosen)
    for k in range(n):
        if _window(chunks[out[k]], lo + k) == target[k]:
            continue
        same = [i for i, c in enumerate(chunks) if c.start <= lo + k < c.end and _window(c, lo + k) == target[k]]
        if same:
            out[k] = same[0]
    return out


def _window(chunk, frame: int):
    """The temporal window ``[first, last]`` (input frames) ``chunk`` took ``frame``'s pose from, or None."""
    rows = (chunk.provenance.get("report") or {}).get("frames")
    if not isinstance(rows, list) or len(rows) != len(chunk.poses):
        return None
    row = rows[frame - chunk.start]
    return row.get("window") if isinstance(row, dict) else None


def disagreements(chunks, agree_mm: float) -> list:
    """The cuts (:func:`cut_differences`) where ``chunks`` (any order; sorted here) differ by more than
    ``agree_mm``; their ``indices`` refer to the chunks sorted by start."""
    chunks = sorted(chunks, key=lambda c: (c.start, c.end))
    return [c for c in cut_differences(chunks, _choose(chunks), chunks[0].start) if differs(c, agree_mm)]


def disagreement_text(cut: dict, chunks) -> str:
    """A message for a cut whose chunks disagree, with the command that repairs it."""
    i, j = cut["indices"]
    k = chunks[j].start - chunks[i].start
    return (f"{cut['chunks'][0]} and {cut['chunks'][1]} disagree on frame {cut['frame']} {gap_text(cut)} "
            f"(the later chunk started on another solution); track "
            f"{cut['chunks'][1]}'s frames again with --start-pose {cut['chunks'][0]}:{k}, or give more overlap, "
            f"or accept the join as it is with --agree 0")


def merge_chunks(chunks, agree_mm: float = None) -> MergedTrack:
    """Join tracked chunks (any order) into one track over the union of their frames (module docstring).
    Raises :class:`ArticulaInputError` naming the chunks when they do not belong together, leave a gap,
    do not overlap or disagree on a shared frame's name, or, with ``agree_mm`` (mm; None or 0: no
    check), when their posed vertices differ by more than that at a cut (:func:`cut_differences`)."""
    if len(chunks) < 2:
        raise ArticulaInputError(f"{len(chunks)} chunk given; merging needs at least two tracked chunks")
    chunks = sorted(chunks, key=lambda c: (c.start, c.end))
    _check_compatible(chunks)
    _check_coverage(chunks)
    lo, hi = chunks[0].start, chunks[-1].end
    chosen = _choose(chunks)
    cuts = cut_differences(chunks, chosen, lo)
    bad = [c for c in cuts if differs(c, agree_mm)]
    if bad:
        raise ArticulaInputError(disagreement_text(bad[0], chunks))
    idx = [lo + k - chunks[i].start for k, i in enumerate(chosen)]
    poses = Poses(np.stack([chunks[i].poses.rotations[j] for i, j in zip(chosen, idx)]),
                  np.stack([chunks[i].poses.translations[j] for i, j in zip(chosen, idx)]),
                  np.array([chunks[i].poses.scales[j] for i, j in zip(chosen, idx)]))
    counts = np.bincount(chosen, minlength=len(chunks))
    keep = int(np.argmax(counts))
    spread = max(float(np.abs(c.model.rest_vertices - chunks[keep].model.rest_vertices).max()) for c in chunks)
    names = [chunks[i].provenance["frame_names"][j] for i, j in zip(chosen, idx)]
    rows = _merged_frame_rows(chunks, chosen, lo)
    report = {"chunks": [{"name": c.name, "frames": [c.start, c.end], "used": int(counts[i])}
                         for i, c in enumerate(chunks)],
              "frame_chunk": [int(i) for i in chosen], "first_frame": lo, "frames": hi - lo,
              "overlaps": [_overlap_differences(p, c) for p, c in zip(chunks, chunks[1:])], "cuts": cuts,
              "model_from": chunks[keep].name, "model_spread_mm": 1000 * spread}
    if rows:
        report["frame_rows"] = rows
        report["lost"] = [lo + k for k, r in enumerate(rows) if r.get("lost")]
        report["skipped"] = [lo + k for k, r in enumerate(rows) if r.get("skipped")]
    ref = chunks[0].provenance
    prov = track_provenance(ref["model_sha256"], ref["input"]["source"], ref["input"]["frames"], lo, names,
                            ref["options"], ref["adapted"], {"merge": report})
    prov.update({k: ref[k] for k in ("tracker", "coordinates", "template", "look_ahead") if k in ref})
    return MergedTrack(chunks[keep].model, poses, prov, report)
