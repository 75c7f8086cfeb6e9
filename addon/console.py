"""Keep the terminal honest: Blender and its bundled add-ons print lines that read like failures but are
not (EGL context errors of a headless render that succeeds, the glTF exporter's "ERROR ... is not
available" for the optional Draco and MeshOptimizer libraries a bpy build lacks, "Read blend:" when a
file is opened).  :func:`without_lines` runs a block with the process's stdout and stderr captured at
the file-descriptor level (C output and Python's alike), then prints every captured line except those
matching the given patterns, to the stream it was going to: real errors still show.
"""
from __future__ import annotations

import contextlib
import ctypes
import io
import os
import re
import sys
import tempfile

# bpy 4.2 prints it once, 5.2 three times, when a headless process creates its first GPU context.
EGL = re.compile(r"^EGL Error \(0x3009\): EGL_BAD_MATCH")
# io_scene_gltf2 (4.2: "Draco mesh compression", 5.2: "Draco", "MeshOptimizer") on every export.
GLTF_LIBRARIES = re.compile(r"^(ERROR|WARNING) (Draco( mesh compression)?|MeshOptimizer) is not available "
                            r"because (the )?library could not be found at ")
# wm.open_mainfile: 4.2 'Read blend: "<path>"', 5.2 '00:01.029  blend  | Read blend: "<path>"'.
READ_BLEND = re.compile(r'^(\d+:\d\d\.\d+\s+blend\s+\|\s+)?Read blend: "')


def _flush_c_streams() -> None:
    """Flush C stdio buffers (Blender's printf output) so it reaches the file descriptors now."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


def _flush_python_streams() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, ValueError, OSError):
            pass


def kept_lines(text: str, patterns) -> str:
    """``text`` without the lines that match one of ``patterns`` (compiled regular expressions)."""
    return "".join(line for line in text.splitlines(keepends=True)
                   if not any(p.search(line) for p in patterns))


@contextlib.contextmanager
def without_lines(*patterns):
    """Run the block with file descriptors 1 and 2 (and ``sys.stdout`` / ``sys.stderr``, which may be
    other objects, e.g. under a test runner) sent to temporary files; afterwards write the captured
    lines that match none of ``patterns`` to ``sys.stdout`` / ``sys.stderr``, also when the block
    raises.  Python and C output share one file per stream, so their order is kept."""
    _flush_python_streams()
    _flush_c_streams()
    python_streams = (sys.stdout, sys.stderr)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        saved = {fd: os.dup(fd) for fd in (1, 2)}
        writers = []
        try:
            for fd, captured in ((1, out), (2, err)):
                os.dup2(captured.fileno(), fd)
                writers.append(io.TextIOWrapper(io.FileIO(os.dup(captured.fileno()), "wb"), encoding="utf-8",
                                                errors="replace", line_buffering=True, write_through=True))
            sys.stdout, sys.stderr = writers
            yield
        finally:
            _flush_c_streams()
            sys.stdout, sys.stderr = python_streams
            for writer in writers:
                writer.close()
            for fd, old in saved.items():
                os.dup2(old, fd)
                os.close(old)
            for captured, stream in ((out, sys.stdout), (err, sys.stderr)):
                captured.seek(0)
                kept = kept_lines(captured.read().decode("utf-8", errors="replace"), patterns)
                if kept:
                    stream.write(kept)
                    stream.flush()
