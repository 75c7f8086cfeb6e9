"""Grayscale PNG files for depth images: a pure numpy + zlib reader and writer.

Depth frames are stored as 16-bit grayscale PNGs holding millimetres (0 = no measurement), the
format Kinect tools (OpenNI, libfreenect, Skeltrack, TUM RGB-D) use.  This module does not depend
on Pillow or OpenImageIO.

Reader (:func:`read_png16`): bit depth 8 or 16, colour types 0 (gray), 2 (RGB), 4 (gray+alpha) and
6 (RGBA); colour images yield channel 0.  Non-interlaced only.  All five row filters of the PNG
specification (§9: None, Sub, Up, Average, Paeth) are undone:

* None and Sub rows do not depend on the row above: Sub is a cumulative sum along the row per byte
  lane (uint8 sums wrap modulo 256, which is the filter arithmetic);
* runs of Up/Average/Paeth rows that contain an Average or Paeth row are undone by one
  *wavefront* over all such runs: pixel (r, x) depends only on (r, x-1), (r-1, x) and (r-1, x-1),
  so all pixels with equal x + (row index within its run) are independent.  The runs are stored
  skewed side by side, so every step is a plain slice: W + (longest run) vectorised steps instead
  of H·W scalar ones;
* the remaining Up rows are a segmented cumulative sum down the columns.

:func:`read_png16_many` unfilters several frames in one wavefront (fewer, larger numpy steps), which
pays off on files with Average/Paeth rows (libpng-encoded Kinect frames); ``./run bench depth`` times it.

Writer (:func:`write_png16`): uint16 (or uint8) (H, W) arrays as grayscale PNG with a chosen
filter per row (any of the five, vectorised because forward filtering only reads raw bytes).
Files are written atomically (temporary file, then rename).

Chunk CRCs are verified; problems raise :class:`~.errors.ArticulaInputError` naming the file.  Files
are read chunk by chunk: the signature and IHDR come first, the image size they declare is checked
against :data:`MAX_FRAME_BYTES` and the file size against what such an image can take, and the
image data is inflated no further than the declared size (a "zip bomb" cannot fill the memory).
"""
from __future__ import annotations

import io
import os
import struct
import zlib

import numpy as np

from ..errors import ArticulaInputError
from .atomic import written_through
from .bounded import file_size, open_file, size_text

SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The largest image read (its uncompressed bytes, W x H x bytes per pixel): 16384 x 16384 16-bit gray.
MAX_FRAME_BYTES = 16384 * 16384 * 2
#: Bytes a PNG file may hold beyond its uncompressed image (ancillary chunks, deflate overhead).
_PNG_SLACK_BYTES = 16_000_000
FILTER_NAMES = ("none", "sub", "up", "average", "paeth")
_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}  # colour type -> samples per pixel


# ----------------------------------------------------------------------------------------- reading

def read_png16(path) -> np.ndarray:
    """Read a grayscale (or channel 0 of a colour) PNG.

    Returns an (H, W) array: uint16 for 16-bit files, uint8 for 8-bit files (use
    ``.astype(np.uint16)`` when a uniform type is needed).  For depth PNGs the values are
    millimetres with 0 meaning "no measurement".
    """
    path = os.fspath(path)
    info, filtered, ftypes = _inflate_file(path)
    return _samples(unfilter(filtered, ftypes), info[2])


def read_png_header(path) -> tuple:
    """``(width, height, bit depth, colour type)`` from a PNG's first 33 bytes, checked as when reading
    (signature, IHDR, supported format, declared size against the limit and the file size)."""
    path = os.fspath(path)
    with open_file(path) as f:
        return _start(f, path, file_size(f))


def decode_png(data: bytes, name: str = "<bytes>") -> np.ndarray:
    """Decode PNG file contents (see :func:`read_png16`); ``name`` is used in error messages."""
    info, filtered, ftypes = _inflate(io.BytesIO(data), name, len(data))
    return _samples(unfilter(filtered, ftypes), info[2])


def read_png16_many(paths, batch: int = 8) -> list:
    """Read several PNGs (e.g. the frames of a depth recording); same result as
    ``[read_png16(p) for p in paths]``, but frames of equal width and pixel format are unfiltered
    together, ``batch`` at a time, which amortises the per-step cost of the Average/Paeth wavefront
    (several times faster on libpng-encoded frames)."""
    parsed = [_inflate_file(os.fspath(p)) for p in paths]
    out = [None] * len(parsed)
    groups = {}
    for i, (info, filtered, ftypes) in enumerate(parsed):
        if ftypes.max(initial=0) < 3:      # no wavefront needed: nothing to share
            out[i] = _samples(unfilter(filtered, ftypes), info[2])
        else:
            groups.setdefault((filtered.shape[1:], info[2]), []).append(i)
    for (_, depth), members in groups.items():
        for k in range(0, len(members), max(1, int(batch))):
            chunk = members[k:k + batch]
            heights = [parsed[i][1].shape[0] for i in chunk]
            first = np.zeros(sum(heights), bool)
            first[np.r_[0, np.cumsum(heights)[:-1]]] = True
            stacked = unfilter(np.concatenate([parsed[i][1] for i in chunk]),
                               np.concatenate([parsed[i][2] for i in chunk]), first)
            for i, part in zip(chunk, np.split(stacked, np.cumsum(heights)[:-1])):
                out[i] = _samples(part, depth)
    return out


def _inflate_file(path: str):
    with open_file(path) as f:
        return _inflate(f, path, file_size(f))


def _inflate(f, name: str, size=None):
    """Validate and decompress the PNG read from file object ``f`` (or bytes; ``size``: bytes, None if
    unknown): ((W, H, depth, ctype), filtered (H, W, bpp) uint8, types (H,))."""
    if isinstance(f, (bytes, bytearray, memoryview)):
        f, size = io.BytesIO(f), len(f)
    header = _start(f, name, size)
    width, height, depth, ctype = header
    bpp = _CHANNELS[ctype] * depth // 8
    stride = width * bpp + 1
    raw = _inflate_chunks(f, name, stride * height, _chunk_limit(stride * height))
    if len(raw) < stride * height:
        raise ArticulaInputError(f"{name}: PNG image data too short ({len(raw)} bytes, "
                                 f"expected {stride * height} for {width}x{height})")
    rows = np.frombuffer(raw, np.uint8, stride * height).reshape(height, stride)
    ftypes = rows[:, 0]
    if ftypes.max(initial=0) > 4:
        bad = int(np.argmax(ftypes > 4))
        raise ArticulaInputError(f"{name}: invalid PNG filter type {int(ftypes[bad])} in image row {bad + 1}")
    return header, rows[:, 1:].reshape(height, width, bpp), ftypes


def _chunk_limit(raw_size: int) -> int:
    """The most bytes a PNG of ``raw_size`` uncompressed image bytes can sensibly take."""
    return raw_size + raw_size // 64 + _PNG_SLACK_BYTES


def _start(f, name: str, size):
    """Check the signature and the IHDR chunk (read from ``f``), the declared image against
    :data:`MAX_FRAME_BYTES` and the file ``size`` against it; ``(W, H, depth, ctype)``."""
    if f.read(8) != SIGNATURE:
        raise ArticulaInputError(f"{name}: not a PNG file (bad signature)")
    length, kind, body = _chunk(f, name, 64)
    if kind != b"IHDR":
        raise ArticulaInputError(f"{name}: PNG without IHDR chunk (the first chunk is {kind!r})")
    header = _check_header(body, name)
    width, height, depth, ctype = header
    raw = (width * _CHANNELS[ctype] * depth // 8 + 1) * height
    if raw > MAX_FRAME_BYTES:
        raise ArticulaInputError(f"{name}: the PNG header declares a {width}x{height} image "
                                 f"({size_text(raw)} uncompressed), larger than the {size_text(MAX_FRAME_BYTES)} "
                                 "limit for a single frame")
    if size is not None and size > _chunk_limit(raw):
        raise ArticulaInputError(f"{name}: {size_text(size)} is far larger than a {width}x{height} PNG image can "
                                 f"take ({size_text(raw)} uncompressed); not a valid depth frame")
    return header


def _chunk(f, name: str, limit: int):
    """Read one chunk (length, type, body; CRC verified); bodies over ``limit`` bytes are refused
    before they are read."""
    head = f.read(8)
    if len(head) < 8:
        raise ArticulaInputError(f"{name}: truncated PNG (no IEND chunk)")
    length, kind = struct.unpack(">I4s", head)
    if length > limit:
        raise ArticulaInputError(f"{name}: PNG chunk {kind!r} declares {size_text(length)}, more than this "
                                 f"image can hold ({size_text(limit)})")
    body = f.read(length)
    crc = f.read(4)
    if len(body) != length or len(crc) != 4:
        raise ArticulaInputError(f"{name}: truncated PNG chunk {kind!r}")
    if zlib.crc32(kind + body) & 0xFFFFFFFF != struct.unpack(">I", crc)[0]:
        raise ArticulaInputError(f"{name}: CRC mismatch in PNG chunk {kind.decode('latin1')!r}")
    return length, kind, body


def _inflate_chunks(f, name: str, raw_size: int, limit: int) -> bytes:
    """The image data of the chunks after IHDR, inflated as the IDAT chunks come and never beyond
    ``raw_size`` bytes; stops at IEND."""
    inflater, parts, got, seen = zlib.decompressobj(), [], 0, False
    while True:
        _, kind, body = _chunk(f, name, limit)
        if kind == b"IEND":
            break
        if kind != b"IDAT":
            continue
        seen = True
        try:
            part = inflater.decompress(body, raw_size + 1 - got)
        except zlib.error as exc:
            raise ArticulaInputError(f"{name}: corrupt PNG image data ({exc})") from exc
        got += len(part)
        parts.append(part)
        if got > raw_size or inflater.unconsumed_tail:
            raise ArticulaInputError(f"{name}: PNG image data is larger than its declared size")
    if not seen:
        raise ArticulaInputError(f"{name}: PNG without IDAT chunk")
    return b"".join(parts)


def _samples(pixels, depth):
    """Channel 0 of unfiltered (H, W, bpp) bytes: uint16 (big-endian in the file) or uint8."""
    if depth == 16:
        return (pixels[:, :, 0].astype(np.uint16) << 8) | pixels[:, :, 1]
    return np.ascontiguousarray(pixels[:, :, 0])


def _check_header(body: bytes, name: str):
    if len(body) != 13:
        raise ArticulaInputError(f"{name}: malformed PNG IHDR chunk")
    width, height, depth, ctype, comp, filt, interlace = struct.unpack(">IIBBBBB", body)
    if width == 0 or height == 0:
        raise ArticulaInputError(f"{name}: empty PNG image ({width}x{height})")
    if ctype not in _CHANNELS:
        kind = {3: "palette"}.get(ctype, f"unknown ({ctype})")
        raise ArticulaInputError(f"{name}: PNG colour type {ctype} ({kind}) is not supported; "
                                 "expected grayscale (0), RGB (2), gray+alpha (4) or RGBA (6)")
    if depth not in (8, 16):
        raise ArticulaInputError(f"{name}: PNG bit depth {depth} is not supported; expected 8 or 16 "
                                 "(depth images are 16-bit)")
    if comp != 0 or filt != 0:
        raise ArticulaInputError(f"{name}: unknown PNG compression/filter method ({comp}, {filt})")
    if interlace != 0:
        raise ArticulaInputError(f"{name}: interlaced (Adam7) PNG is not supported; save it "
                                 "non-interlaced")
    return width, height, depth, ctype


def unfilter(filtered: np.ndarray, ftypes: np.ndarray, first=None) -> np.ndarray:
    """Undo PNG row filters.

    ``filtered``: (H, W, bpp) uint8 filtered bytes (without the filter-type byte), bpp = bytes per
    pixel; ``ftypes``: (H,) filter type per row (0..4); ``first``: optional (H,) bool marking rows
    that start an image (their "row above" is zero), so several images stacked row-wise are
    unfiltered together (default: one image).  Returns the (H, W, bpp) uint8 raw bytes.

    Order: None and Sub rows do not depend on the row above and are undone first; then every run
    of dependent rows (Up/Average/Paeth) that holds an Average or Paeth row, all runs together in one
    wavefront; last the remaining Up rows by a segmented cumulative sum.
    """
    ftypes = np.asarray(ftypes)
    if first is None:
        first = np.zeros(len(ftypes), bool)
        first[:1] = True
    out = filtered.copy()
    sub = ftypes == 1
    if sub.any():
        out[sub] = np.cumsum(filtered[sub], axis=1, dtype=np.uint8)
    known = (ftypes <= 1) | (first & (ftypes == 2))  # Up below a zero row: the bytes themselves
    runs = _hard_runs(ftypes, first)
    if runs:
        _unfilter_wavefront(filtered, ftypes, out, runs)
        for start, stop, _ in runs:
            known[start:stop] = True
    if not known.all():
        out = _unfilter_up(out, known)
    return out


def _hard_runs(ftypes, first):
    """[(start, stop, has_prior)]: maximal runs of dependent rows (type >= 2) within one image that
    contain an Average/Paeth row; has_prior is False for runs starting an image."""
    dep = ftypes >= 2
    starts = np.flatnonzero(dep & (first | ~np.r_[False, dep[:-1]]))
    ends = np.flatnonzero(dep & (np.r_[first[1:], True] | ~np.r_[dep[1:], False])) + 1
    hard = np.r_[0, np.cumsum(ftypes >= 3)]
    return [(a, b, not first[a]) for a, b in zip(starts.tolist(), ends.tolist()) if hard[b] > hard[a]]


def _unfilter_up(rec, known):
    """Rows not ``known`` are Up rows: each adds the row above; within a run this is a cumulative
    sum (uint8, wrapping like the filter arithmetic) from the last known row."""
    v = np.concatenate([np.zeros((1,) + rec.shape[1:], np.uint8), rec])
    csum = np.cumsum(v, axis=0, dtype=np.uint8)
    base = np.maximum.accumulate(np.where(np.r_[True, known], np.arange(len(v)), 0))
    return (csum - csum[base] + v[base])[1:]


def _unfilter_wavefront(filtered, ftypes, out, runs):
    """Undo the filters of ``runs`` (their prior rows are already in ``out``), all runs at once.

    Columns of the skewed work array: a zero column, then per run its prior row followed by its
    rows.  Pixel x of the row with in-run index i (prior: -1) sits at ``k[x + i + 2, column]``, so at
    step s the left (a), up (b) and up-left (c) neighbours of all pixels with x = s - i are plain
    slices.  Steps: W + longest run.  Prior rows enter as Sub-filtered copies of their known bytes,
    so every column follows the same recurrence.
    """
    _, width, bpp = filtered.shape
    ncol = 1 + sum(stop - start + 1 for start, stop, _ in runs)
    longest = max(stop - start for start, stop, _ in runs)
    f = np.zeros((width + longest + 2, ncol, bpp), np.int16)
    k = np.zeros_like(f)
    kind = np.ones(ncol, np.int64)           # prior rows (and the zero column) act as Sub rows
    local = np.full(ncol, -1)
    col = 1
    for start, stop, has_prior in runs:
        n = stop - start
        prior = out[start - 1].astype(np.int16) if has_prior else np.zeros((width, bpp), np.int16)
        view = _skewed(f, col, n + 1, width)
        view[0, 0] = prior[0]
        view[0, 1:] = (prior[1:] - prior[:-1]) & 255
        view[1:] = filtered[start:stop]
        k[1, col] = prior[0]                 # x = 0 of the prior row (step -1 is never run)
        kind[col + 1:col + 1 + n] = ftypes[start:stop]
        local[col + 1:col + 1 + n] = np.arange(n)
        col += n + 1
    kk = np.broadcast_to(kind[1:, None], (ncol - 1, bpp))
    is_sub, is_up, is_avg = kk == 1, kk == 2, kk == 3
    any_up, any_avg = bool(is_up.any()), bool(is_avg.any())
    # after step s, the x = -1 slot of columns with local == s + 1 must be zero again
    order = np.argsort(local[1:], kind="stable")
    bounds = np.searchsorted(local[1:][order], np.arange(longest + 1) + 1)
    for s in range(width + longest):
        a, b, c = k[s + 1, 1:], k[s + 1, :-1], k[s, :-1]
        pred = _paeth(a, b, c)
        if any_avg:
            pred = np.where(is_avg, (a + b) >> 1, pred)
        if any_up:
            pred = np.where(is_up, b, pred)
        pred = np.where(is_sub, a, pred)
        pred += f[s + 2, 1:]
        np.bitwise_and(pred, 255, out=k[s + 2, 1:])
        if s < longest - 1:
            k[s + 2, order[bounds[s]:bounds[s + 1]] + 1] = 0
    col = 1
    for start, stop, _ in runs:
        out[start:stop] = _skewed(k, col, stop - start + 1, width)[1:]
        col += stop - start + 1


def _skewed(arr, col, n, width):
    """View ``v[i, x] = arr[x + i + 1, col + i]`` (i = 0 is a run's prior row, in-run index -1)."""
    s0, s1, s2 = arr.strides
    return np.lib.stride_tricks.as_strided(arr[1:, col:], shape=(n, width, arr.shape[2]),
                                           strides=(s0 + s1, s0, s2), writeable=True)


def _paeth(a, b, c):
    """Paeth predictor (PNG spec §9.4) on integer arrays (int16, values 0..255)."""
    bc, ac = b - c, a - c
    pa, pb, pc = np.abs(bc), np.abs(ac), np.abs(bc + ac)
    return np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))


# ----------------------------------------------------------------------------------------- writing

def write_png16(path, image, filter_type="up", level: int = 6) -> None:
    """Write a (H, W) uint16 (16-bit) or uint8 (8-bit) array as a grayscale PNG, atomically.

    ``filter_type``: one of :data:`FILTER_NAMES` or 0..4 for every row, or an (H,) sequence of
    per-row types.  ``up`` (default) compresses depth images well and decodes fastest.
    ``level``: zlib level 0..9.
    """
    path = os.fspath(path)
    data = encode_png(image, filter_type, level, name=path)
    tmp = f"{path}.part{os.getpid()}"
    with written_through(path, tmp, "PNG"), open(tmp, "wb") as f:
        f.write(data)


def encode_png(image, filter_type="up", level: int = 6, name: str = "<image>") -> bytes:
    """PNG file contents for a (H, W) uint16 or uint8 array (see :func:`write_png16`)."""
    image = np.asarray(image)
    if image.ndim != 2 or image.shape[0] == 0 or image.shape[1] == 0:
        raise ArticulaInputError(f"{name}: expected a non-empty (H, W) image, got shape {image.shape}")
    if image.dtype == np.uint16:
        depth, raw = 16, image.astype(">u2").view(np.uint8).reshape(*image.shape, 2)
    elif image.dtype == np.uint8:
        depth, raw = 8, image[:, :, None]
    else:
        raise ArticulaInputError(f"{name}: PNG image must be uint16 or uint8, got {image.dtype}")
    types = _filter_types(filter_type, image.shape[0], name)
    filtered = apply_filters(raw, types)
    rows = np.concatenate([types[:, None].astype(np.uint8),
                           filtered.reshape(image.shape[0], -1)], axis=1)
    height, width = image.shape
    ihdr = struct.pack(">IIBBBBB", width, height, depth, 0, 0, 0, 0)
    return (SIGNATURE + _make_chunk(b"IHDR", ihdr) + _make_chunk(b"IDAT", zlib.compress(rows.tobytes(), level))
            + _make_chunk(b"IEND", b""))


def _filter_types(filter_type, height, name):
    if isinstance(filter_type, str):
        if filter_type not in FILTER_NAMES:
            raise ArticulaInputError(f"{name}: unknown PNG filter {filter_type!r}; "
                                     f"expected one of {', '.join(FILTER_NAMES)}")
        filter_type = FILTER_NAMES.index(filter_type)
    types = np.broadcast_to(np.asarray(filter_type), (height,)).astype(np.int64)
    if types.min() < 0 or types.max() > 4:
        raise ArticulaInputError(f"{name}: PNG filter types must be 0..4")
    return types


def apply_filters(raw: np.ndarray, types: np.ndarray) -> np.ndarray:
    """Forward PNG filters: (H, W, bpp) uint8 raw bytes, (H,) types -> (H, W, bpp) uint8.

    Only the predictors of the types present are computed, each on its rows only."""
    out = raw.copy()
    for t in np.unique(types).tolist():
        rows = np.flatnonzero(types == t)
        cur = raw[rows]
        a = np.zeros_like(cur)
        a[:, 1:] = cur[:, :-1]
        up = np.where((rows > 0)[:, None, None], raw[np.maximum(rows - 1, 0)], 0).astype(np.uint8)
        if t == 1:
            out[rows] = cur - a
        elif t == 2:
            out[rows] = cur - up
        elif t == 3:
            out[rows] = cur - ((a.astype(np.int16) + up) >> 1).astype(np.uint8)
        elif t == 4:
            c = np.zeros_like(up)
            c[:, 1:] = up[:, :-1]
            out[rows] = cur - _paeth(a.astype(np.int16), up.astype(np.int16), c.astype(np.int16)).astype(np.uint8)
    return out


def _make_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
