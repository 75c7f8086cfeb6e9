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
"""
from __future__ import annotations

import os
import struct

import numpy as np

from ..errors import ArticulaInputError
from .polymesh import read_bytes

CACHE_EXTENSIONS = (".mdd", ".pc2")


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
        raise ArticulaInputError(f"{path}: frame {f} vertex {v} has a non-finite coordinate "
                                 f"{frames[f, v].tolist()}")
    return frames


def read_mdd(path: str) -> np.ndarray:
    data = read_bytes(path)
    if len(data) < 8:
        raise ArticulaInputError(f"{path}: too short for an MDD file ({len(data)} bytes)")
    frames, points = struct.unpack_from(">2i", data)
    if frames <= 0 or points <= 0:
        raise ArticulaInputError(f"{path}: not an MDD file (header says {frames} frames, {points} points)")
    start = 8 + 4 * frames
    frame_bytes = 12 * points
    size = len(data) - start
    if size == frames * frame_bytes:
        skip = 0
    elif size == (frames + 1) * frame_bytes:
        skip = 1  # a leading rest-pose frame
    else:
        raise ArticulaInputError(f"{path}: MDD header says {frames} frames of {points} points "
                                 f"({8 + 4 * frames + frames * frame_bytes} bytes) but the file has "
                                 f"{len(data)} bytes")
    pos = np.frombuffer(data, ">f4", (frames + skip) * points * 3, start).reshape(-1, points, 3)[skip:]
    return _check(pos.astype(np.float32), path)


def read_pc2(path: str) -> np.ndarray:
    data = read_bytes(path)
    if len(data) < 32 or data[:12] != b"POINTCACHE2\0":
        raise ArticulaInputError(f"{path}: not a PC2 file (no POINTCACHE2 header)")
    _version, points, _start, _rate, samples = struct.unpack_from("<iiffi", data, 12)
    if points <= 0 or samples <= 0:
        raise ArticulaInputError(f"{path}: PC2 header says {samples} samples of {points} points")
    need = 32 + samples * points * 12
    if len(data) < need:
        raise ArticulaInputError(f"{path}: PC2 header says {samples} samples of {points} points "
                                 f"({need} bytes) but the file has {len(data)} bytes")
    pos = np.frombuffer(data, "<f4", samples * points * 3, 32).reshape(samples, points, 3)
    return _check(pos.astype(np.float32), path)
