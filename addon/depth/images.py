"""Images read through Blender for a depth import: EXR depth frames and colour frames (PNG/JPG).
Main thread only (``bpy.data.images``); the operator reads them before its worker starts.
"""
import os

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.formats.bounded import check_size, read_head
from ...solver.formats.png16 import MAX_FRAME_BYTES

# first bytes of the image files Blender is asked to read (checked before it reads the whole file)
MAGIC = {"OpenEXR": (b"v/1\x01",), "PNG": (b"\x89PNG\r\n\x1a\n",), "JPEG": (b"\xff\xd8\xff",)}


def load_image_pixels(path: str, what: str, formats=("PNG", "JPEG")) -> np.ndarray:
    """(H, W, 4) float32 pixels of an image file read by Blender (rows top to bottom, as stored in
    the file), values as stored (no colour management).  The file must start like one of ``formats``
    (:data:`MAGIC`) and be within ``png16.MAX_FRAME_BYTES`` before Blender reads it.  Main thread only."""
    if not os.path.isfile(path):
        raise ArticulaInputError(f"{path}: {what} file missing")
    head, size = read_head(path, 8)
    if not any(head.startswith(m) for f in formats for m in MAGIC[f]):
        raise ArticulaInputError(f"{path}: not a {' or '.join(formats)} file ({what})")
    check_size(path, size, MAX_FRAME_BYTES, f"a single {what}", "use smaller frames")
    try:
        img = bpy.data.images.load(path, check_existing=False)
    except RuntimeError as exc:
        raise ArticulaInputError(f"{path}: cannot read {what} ({exc})") from exc
    try:
        try:
            img.colorspace_settings.is_data = True
        except (AttributeError, TypeError):
            pass
        w, h = img.size
        if w == 0 or h == 0:
            raise ArticulaInputError(f"{path}: cannot read {what} (empty or unsupported image)")
        buf = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(buf)
        return buf.reshape(h, w, 4)[::-1]
    finally:
        bpy.data.images.remove(img)


def load_exr_depth(path: str) -> np.ndarray:
    """Depth from an OpenEXR (or other float) image: the first channel, in metres, (H, W) float32."""
    return np.ascontiguousarray(load_image_pixels(path, "EXR depth frame", ("OpenEXR",))[:, :, 0])


def load_color(path: str) -> np.ndarray:
    """An 8-bit colour frame (PNG/JPG) as (H, W, 3) uint8 (sRGB values as stored)."""
    px = load_image_pixels(path, "colour frame")
    return np.clip(px[:, :, :3] * 255 + 0.5, 0, 255).astype(np.uint8)
