"""Bounded file reading shared by every reader: a file's first bytes are validated (magic, header) and
its size is checked against what the header declares and against a limit *before* the file is read whole,
so a huge or wrong file is refused in milliseconds without filling the memory (docs/scans.md, Limits).

The limits are module constants so a caller (or a user's script) can raise them.
"""
from __future__ import annotations

import os

from ..errors import ArticulaInputError

#: The largest single scan, point-cloud frame or rig file read (bytes).  Parsing a text mesh takes several
#: times its size in memory (docs/scans.md, Limits).
MAX_SCAN_BYTES = 1_000_000_000
#: Bytes of a text file's beginning that are checked to look like its format.
HEAD_BYTES = 4096


def size_text(n: float) -> str:
    """Bytes as a short human-readable size (``2.1 GB``, ``537 MB``, ``12 kB``, ``352 bytes``)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}" if n < 10 * scale else f"{n / scale:.0f} {unit}"
    return f"{int(n)} bytes"


def open_file(path: str):
    """``open(path, 'rb')`` with clear errors for a missing, folder or unreadable path."""
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise ArticulaInputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ArticulaInputError(f"{path}: is a folder, not a file") from None
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot read ({exc.strerror or exc})") from None


def file_size(f) -> int | None:
    """Size of an open regular file in bytes; None for pipes and devices (their size is unknown)."""
    st = os.fstat(f.fileno())
    return st.st_size if os.path.stat.S_ISREG(st.st_mode) else None


def read_head(path: str, n: int = HEAD_BYTES) -> tuple[bytes, int | None]:
    """``(the first n bytes (fewer for a shorter file), file size or None)``."""
    with open_file(path) as f:
        try:
            return f.read(n), file_size(f)
        except OSError as exc:
            raise ArticulaInputError(f"{path}: cannot read ({exc.strerror or exc})") from None


def check_size(path: str, size: int | None, limit: int = MAX_SCAN_BYTES, what: str = "a single scan",
               hint: str = "decimate the mesh or split the file") -> None:
    """Refuse a file larger than ``limit`` bytes, saying how large it is, what the limit is for and
    what to do (``hint``)."""
    if size is not None and size > limit:
        raise ArticulaInputError(f"{path}: {size_text(size)} is larger than the {size_text(limit)} limit for "
                                 f"{what}; {hint}")


def read_bytes(path: str, limit: int = MAX_SCAN_BYTES, what: str = "a single scan",
               hint: str = "decimate the mesh or split the file") -> bytes:
    """The whole file, refused (before reading) when it is larger than ``limit`` bytes.  Files of unknown
    size (pipes) are read up to ``limit`` + 1 bytes, so they are bounded too."""
    with open_file(path) as f:
        check_size(path, file_size(f), limit, what, hint)
        try:
            data = f.read(limit + 1)
        except OSError as exc:
            raise ArticulaInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    check_size(path, len(data), limit, what, hint)
    return data


def complete_lines(head: bytes, whole: bool) -> list[bytes]:
    """Lines of a file's first bytes; the last (possibly cut) line is dropped unless ``whole`` (the head
    is the entire file)."""
    lines = head.splitlines()
    return lines if whole or head.endswith(b"\n") else lines[:-1]


def all_numbers(tokens) -> bool:
    """Whether every token (bytes or str) of a text line parses as a number: the check the text readers
    use on a file's first lines to tell their format from anything else."""
    try:
        [float(t) for t in tokens]
        return True
    except ValueError:
        return False
