"""16-bit PNG codec: round trips for every filter type, independent decoders, error handling."""
import glob
import importlib.util
import os
import struct
import sys
import zlib

import numpy as np
import pytest

from articula.solver.formats import png16
from articula.solver.errors import ArticulaInputError

from ...conftest import SHARED_DATA

KINECT_DIR = os.path.join(SHARED_DATA, "depth", "skeltrack_kinect")


def _depth_like(seed, shape=(48, 64)):
    """Random depth image: smooth ramp + noise + zero holes, full 16-bit range exercised."""
    rng = np.random.default_rng(seed)
    h, w = shape
    img = (np.add.outer(np.arange(h) * 37, np.arange(w) * 11) + rng.integers(0, 900, shape)) % 65536
    img[rng.random(shape) < 0.2] = 0
    img[0, 0], img[-1, -1] = 65535, 1
    return img.astype(np.uint16)


def _reference_unfilter(rows, bpp):
    """Straightforward per-byte unfiltering, transcribed from the PNG specification §9."""
    out = []
    prior = [0] * (len(rows[0]) - 1)
    for row in rows:
        ftype, cur = row[0], list(row[1:])
        for i in range(len(cur)):
            a = cur[i - bpp] if i >= bpp else 0
            b = prior[i]
            c = prior[i - bpp] if i >= bpp else 0
            if ftype == 0:
                pred = 0
            elif ftype == 1:
                pred = a
            elif ftype == 2:
                pred = b
            elif ftype == 3:
                pred = (a + b) // 2
            else:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            cur[i] = (cur[i] + pred) % 256
        out.append(cur)
        prior = cur
    return out


@pytest.mark.parametrize("ftype", png16.FILTER_NAMES)
def test_round_trip_each_filter(tmp_path, ftype):
    img = _depth_like(1)
    path = tmp_path / f"{ftype}.png"
    png16.write_png16(path, img, filter_type=ftype)
    data = path.read_bytes()
    # the file really uses the requested filter on every row
    raw = zlib.decompress(data[8 + 25 + 8:-12 - 4])
    rows = np.frombuffer(raw, np.uint8).reshape(img.shape[0], -1)
    assert set(rows[:, 0]) == {png16.FILTER_NAMES.index(ftype)}
    back = png16.read_png16(path)
    assert back.dtype == np.uint16 and back.shape == img.shape
    np.testing.assert_array_equal(back, img)


def test_mixed_filters_and_8bit():
    rng = np.random.default_rng(2)
    img = _depth_like(3, (70, 90))
    types = rng.integers(0, 5, img.shape[0])
    types[10:20] = 4  # a run of Paeth rows next to runs of single rows
    np.testing.assert_array_equal(png16.decode_png(png16.encode_png(img, types)), img)
    img8 = rng.integers(0, 256, (33, 17)).astype(np.uint8)
    back = png16.decode_png(png16.encode_png(img8, rng.integers(0, 5, 33)))
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, img8)


def test_unfilter_matches_specification_transcription():
    """The vectorised unfilter equals a literal per-byte transcription of the spec, for random
    filter sequences (runs at the top, single rows, 1-pixel-wide images, 1..4 bytes per pixel)."""
    rng = np.random.default_rng(4)
    for trial in range(120):
        h, w, bpp = int(rng.integers(1, 9)), int(rng.integers(1, 8)), int(rng.integers(1, 5))
        filtered = rng.integers(0, 256, (h, w, bpp)).astype(np.uint8)
        types = rng.integers(0, 5, h) if trial % 3 else np.full(h, rng.integers(2, 5))
        rows = [[int(t)] + filtered[i].ravel().tolist() for i, t in enumerate(types)]
        expected = np.array(_reference_unfilter(rows, bpp), np.uint8).reshape(filtered.shape)
        np.testing.assert_array_equal(png16.unfilter(filtered, types), expected, err_msg=str(types))


def _png(width, height, depth, ctype, raw_rows, interlace=0):
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, depth, ctype, 0, 0, interlace)
    return (png16.SIGNATURE + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw_rows))
            + chunk(b"IEND", b""))


def test_colour_png_returns_channel_0():
    rgba = (np.arange(2 * 3 * 4, dtype=np.uint16).reshape(2, 3, 4) * 1000 + 7)
    rows = b"".join(b"\x00" + r.astype(">u2").tobytes() for r in rgba)
    out = png16.decode_png(_png(3, 2, 16, 6, rows))
    np.testing.assert_array_equal(out, rgba[:, :, 0])


@pytest.mark.parametrize("mutate, message", [
    (lambda d: b"GIF89a" + d[6:], "not a PNG"),
    (lambda d: d[:40], "truncated"),
    (lambda d: d[:20] + bytes([d[20] ^ 1]) + d[21:], "CRC mismatch"),
])
def test_corrupt_files_raise_naming_the_file(tmp_path, mutate, message):
    path = tmp_path / "bad.png"
    path.write_bytes(mutate(png16.encode_png(_depth_like(5))))
    with pytest.raises(ArticulaInputError, match=message) as err:
        png16.read_png16(path)
    assert "bad.png" in str(err.value)


@pytest.mark.parametrize("depth, ctype, interlace, message", [
    (4, 0, 0, "bit depth 4"), (8, 3, 0, "palette"), (16, 0, 1, "interlaced")])
def test_unsupported_formats_raise(tmp_path, depth, ctype, interlace, message):
    path = tmp_path / "odd.png"
    path.write_bytes(_png(4, 2, depth, ctype, b"\x00" * 40, interlace))
    with pytest.raises(ArticulaInputError, match=message):
        png16.read_png16(path)


def test_bad_filter_byte_and_missing_file(tmp_path):
    path = tmp_path / "f.png"
    path.write_bytes(_png(2, 2, 16, 0, b"\x00" + b"\x01" * 4 + b"\x07" + b"\x01" * 4))
    with pytest.raises(ArticulaInputError, match="filter type 7 in image row 2"):
        png16.read_png16(path)
    with pytest.raises(ArticulaInputError, match="missing.png"):
        png16.read_png16(tmp_path / "missing.png")
    with pytest.raises(ArticulaInputError, match="uint16 or uint8"):
        png16.write_png16(tmp_path / "x.png", np.zeros((2, 2), np.float32))


def _openimageio():
    """Blender's bundled OpenImageIO (bpy 5.x wheels ship it beside bpy), or None."""
    spec = importlib.util.find_spec("bpy")  # located, never imported
    if spec is None or not spec.origin:
        return None
    base = os.path.dirname(spec.origin)
    for cand in glob.glob(os.path.join(base, "*", "python", "lib", "python3.*", "site-packages")):
        if os.path.isdir(os.path.join(cand, "OpenImageIO")) and cand not in sys.path:
            sys.path.append(cand)
    try:
        import OpenImageIO
    except ImportError:
        return None
    return OpenImageIO


def test_our_files_decode_identically_in_openimageio(tmp_path):
    oiio = _openimageio()
    if oiio is None:
        pytest.skip("no OpenImageIO in this Blender's Python")
    img = _depth_like(6)
    for ftype in png16.FILTER_NAMES:
        path = str(tmp_path / f"{ftype}.png")
        png16.write_png16(path, img, filter_type=ftype)
        np.testing.assert_array_equal(oiio.ImageBuf(path).get_pixels(oiio.UINT16)[:, :, 0], img)


def _kinect_files():
    files = sorted(glob.glob(os.path.join(KINECT_DIR, "*.png")))
    if not files:
        pytest.skip("shared Kinect depth frames not available")
    return files


def test_real_kinect_frames_sane_and_round_trip(tmp_path):
    """Real libpng-encoded Kinect v1 frames (mixed Sub/Up/Paeth rows): plausible millimetres,
    and re-encoding with every filter gives back the same values."""
    for i, path in enumerate(_kinect_files()):
        depth = png16.read_png16(path)
        assert depth.shape == (480, 640) and depth.dtype == np.uint16
        valid = depth[depth > 0]
        assert 0.05 < valid.size / depth.size < 0.6          # person with background removed
        assert 500 < np.median(valid) < 4000                 # Kinect v1 working range in mm
        again = png16.decode_png(png16.encode_png(depth, png16.FILTER_NAMES[i % 5]))
        np.testing.assert_array_equal(again, depth)


def test_real_kinect_frames_match_openimageio():
    files = _kinect_files()
    oiio = _openimageio()
    if oiio is None:
        pytest.skip("no OpenImageIO in this Blender's Python")
    for path in files:
        ref = oiio.ImageBuf(path).get_pixels(oiio.UINT16)[:, :, 0]
        np.testing.assert_array_equal(png16.read_png16(path), ref)


def test_read_many_equals_one_by_one(tmp_path):
    """Batched decoding (frames stacked in one wavefront) gives each frame exactly; mixed sizes,
    bit depths and filters are grouped correctly; the prior row never leaks between frames."""
    rng = np.random.default_rng(7)
    paths, images = [], []
    for i in range(9):
        shape = (20, 30) if i % 3 else (11, 17)
        img = _depth_like(i, shape)
        if i == 4:
            img = (img % 256).astype(np.uint8)
        types = rng.integers(0, 5, shape[0])
        types[0] = 4 if i % 2 else 2                   # dependent first rows must see zeros above
        path = tmp_path / f"f{i}.png"
        png16.write_png16(path, img, filter_type=types)
        paths.append(path)
        images.append(img)
    got = png16.read_png16_many(paths, batch=4)
    for img, back in zip(images, got):
        assert back.dtype == img.dtype
        np.testing.assert_array_equal(back, img)
    kinect = sorted(glob.glob(os.path.join(KINECT_DIR, "*.png")))[:5]
    for path, back in zip(kinect, png16.read_png16_many(kinect, batch=3)):
        np.testing.assert_array_equal(back, png16.read_png16(path))
