"""Readers for vertex point caches: MDD (big-endian) and PC2.  Pure numpy, no bpy.

Both return all frames as one ``(N, V, 3)`` float32 array.  Neither format stores faces: the
topology comes from a base mesh with the same vertex count.  Coordinates are returned as stored
(no axis conversion).

MDD
    ``int32 frames, int32 points`` (big-endian), ``float32 times[frames]`` (seconds), then
    ``frames x points x 3`` big-endian float32.  Some writers put one extra rest-pose frame before the
    animated frames; when the file is exactly one frame longer than its header says, that first frame
    is skipped.
PC2
    32-byte little-endian header ``char[12] "POINTCACHE2\\0", int32 version (1), int32 points,
    float32 start frame, float32 sample rate, int32 samples``, then ``samples x points x 3`` float32.

The header is read first and the size it declares checked against the file's size and
:data:`MAX_CACHE_BYTES` before the frames are read, block by block, straight into the result.
"""
from __future__ import annotations

import os
import struct

import numpy as np

from ..errors import ArticulaInputError
from .bounded import check_size, open_file, file_size, size_text

CACHE_EXTENSIONS = (".mdd", ".pc2")
#: The largest point cache read (bytes): the whole sequence is held in memory as float32, about the
#: file's size.
MAX_CACHE_BYTES = 4_000_000_000
_BLOCK_VALUES = 1 << 22     # float32 values converted per read (16 MB)


def read_point_cache(path: str) -> np.ndarray:
    """Read an MDD or PC2 file (chosen by extension) -> (N, V, 3) float32."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".mdd":
        return read_mdd(path)
    if ext == ".pc2":
        return read_pc2(path)
    raise ArticulaInputError(f"{path}: unsupported point cache {ext or '(no extension)'!r}; use .mdd or .pc2")


def _check(frames: np.ndarray, path: str) -> np.ndarray:
    bad = ~np.isfinite(frames).all(axis=2)
    if bad.any():
        f, v = (int(i) for i in np.argwhere(bad)[0])
        raise ArticulaInputError(f"{path}: frame {f + 1} vertex {v + 1} has a non-finite coordinate "
                                 f"{frames[f, v].tolist()}")
    return frames


def _read_frames(f, path: str, dtype: str, frames: int, points: int) -> np.ndarray:
    """(frames, points, 3) float32 from the open file's current position, read block by block."""
    out = np.empty(frames * points * 3, np.float32)
    for start in range(0, out.size, _BLOCK_VALUES):
        n = min(_BLOCK_VALUES, out.size - start)
        block = np.frombuffer(f.read(4 * n), dtype)
        if block.size != n:
            raise ArticulaInputError(f"{path}: file ends early (changed while being read?)")
        out[start:start + n] = block
    return out.reshape(frames, points, 3)


def read_mdd(path: str) -> np.ndarray:
    with open_file(path) as f:
        size, data = file_size(f), f.read(8)
        if len(data) < 8:
            raise ArticulaInputError(f"{path}: too short for an MDD file ({len(data)} bytes)")
        frames, points = struct.unpack(">2i", data)
        if frames <= 0 or points <= 0:
            raise ArticulaInputError(f"{path}: not an MDD file (header says {frames} frames, {points} points)")
        start = 8 + 4 * frames
        frame_bytes = 12 * points
        if size is None or size - start == frames * frame_bytes:
            skip = 0
        elif size - start == (frames + 1) * frame_bytes:
            skip = 1  # a leading rest-pose frame
        else:
            raise ArticulaInputError(f"{path}: MDD header says {frames} frames of {points} points "
                                     f"({start + frames * frame_bytes} bytes) but the file has {size} bytes")
        check_size(path, 4 * 3 * frames * points, MAX_CACHE_BYTES, "a point cache", "export fewer frames")
        f.seek(start + skip * frame_bytes)
        return _check(_read_frames(f, path, ">f4", frames, points), path)


def read_pc2(path: str) -> np.ndarray:
    with open_file(path) as f:
        size, data = file_size(f), f.read(32)
        if len(data) < 32 or data[:12] != b"POINTCACHE2\0":
            raise ArticulaInputError(f"{path}: not a PC2 file (no POINTCACHE2 header)")
        _version, points, _start, _rate, samples = struct.unpack_from("<iiffi", data, 12)
        if points <= 0 or samples <= 0:
            raise ArticulaInputError(f"{path}: PC2 header says {samples} samples of {points} points")
        need = 32 + samples * points * 12
        if size is not None and size < need:
            raise ArticulaInputError(f"{path}: PC2 header says {samples} samples of {points} points "
                                     f"({size_text(need)}) but the file has {size_text(size)}")
        check_size(path, need - 32, MAX_CACHE_BYTES, "a point cache", "export fewer frames")
        return _check(_read_frames(f, path, "<f4", samples, points), path)
