"""BVH motion files: the structural check made before Blender's importer reads one (that importer stops
with a Python traceback on a truncated or malformed file).  A BVH is a HIERARCHY of joints, each with
CHANNELS, then MOTION: ``Frames: N``, ``Frame Time: seconds`` and N lines of one number per channel."""
from __future__ import annotations

from ..errors import ArticulaInputError
from .bounded import check_size, file_size, open_file, size_text

#: The largest BVH read (bytes): a long capture at 120 fps is tens of megabytes.
MAX_BVH_BYTES = 500_000_000


def _read_text(path: str) -> str:
    with open_file(path) as f:
        check_size(path, file_size(f), MAX_BVH_BYTES, "a BVH motion", "split the clip")
        try:
            data = f.read(MAX_BVH_BYTES + 1)
        except OSError as exc:
            raise ArticulaInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    check_size(path, len(data), MAX_BVH_BYTES, "a BVH motion", "split the clip")
    return data.decode("latin-1")


def _hierarchy(path: str, lines: list[str]) -> tuple[int, int]:
    """``(channels, index of the MOTION line)``; refuses a file that is not a BVH or whose hierarchy is
    cut off or has no channels."""
    first = next((line.split() for line in lines if line.strip()), [])
    if first[:1] != ["HIERARCHY"]:
        raise ArticulaInputError(f"{path}: not a BVH file (it does not start with HIERARCHY)")
    channels, depth = 0, 0
    for i, line in enumerate(lines):
        words = line.split()
        if words[:1] == ["MOTION"]:
            if depth != 0 or channels == 0:
                break
            return channels, i
        depth += line.count("{") - line.count("}")
        if words[:1] == ["CHANNELS"]:
            try:
                channels += int(words[1])
            except (IndexError, ValueError):
                raise ArticulaInputError(f"{path}: line {i + 1}: CHANNELS needs a count") from None
    raise ArticulaInputError(f"{path}: truncated or malformed BVH: the HIERARCHY does not end in a MOTION section"
                             if channels else f"{path}: the BVH hierarchy has no CHANNELS")


def _header_value(path: str, rows: list, k: int, key: str, kind):
    """The value of header line ``key: value``, the ``k``-th of ``rows`` ((line number, text) after MOTION)."""
    n, line = rows[k] if k < len(rows) else (None, "")
    words = line.replace(":", ": ").split()
    try:
        if " ".join(words[:-1]) != key + ":":
            raise ValueError
        return kind(words[-1])
    except (ValueError, IndexError):
        where = f"line {n} should be" if n else "the file ends before"
        raise ArticulaInputError(f"{path}: truncated or malformed BVH: {where} '{key}: ...'") from None


def check_bvh(path: str) -> tuple[int, int, float]:
    """``(channels, frames, frame time in seconds)`` of the BVH at ``path`` after checking that every one
    of the frames its header declares holds one number per channel; a file cut short or malformed is
    refused with one line naming it and what is wrong."""
    text = _read_text(path)
    lines = text.splitlines()
    channels, motion = _hierarchy(path, lines)
    rows = [(n, line) for n, line in enumerate(lines[motion + 1:], motion + 2) if line.strip()]
    frames = _header_value(path, rows, 0, "Frames", int)
    frame_time = _header_value(path, rows, 1, "Frame Time", float)
    if frames < 1 or not frame_time > 0:
        raise ArticulaInputError(f"{path}: the BVH declares {frames} frames of {frame_time} s: nothing to import")
    rows = rows[2:]
    for k, (n, line) in enumerate(rows[:frames]):
        values = line.split()
        if len(values) != channels:
            cut = " (the file is cut short)" if k == len(rows) - 1 and len(values) < channels else ""
            raise ArticulaInputError(f"{path}: truncated or malformed BVH: frame {k + 1} (line {n}) has "
                                     f"{len(values)} of the {channels} channel values{cut}")
        try:
            [float(v) for v in values]
        except ValueError:
            raise ArticulaInputError(f"{path}: line {n}: frame {k + 1} holds something that is not a number") from None
    if len(rows) < frames:
        raise ArticulaInputError(f"{path}: truncated BVH: it declares {frames} frames but holds {len(rows)} "
                                 f"({size_text(len(text))})")
    return channels, frames, frame_time
