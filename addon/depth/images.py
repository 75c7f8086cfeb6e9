"""Images read through Blender for a depth import: EXR depth frames and colour frames (PNG/JPG).
Main thread only (``bpy.data.images``); the operator reads them before its worker starts.
"""
import os

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError


def load_image_pixels(path: str, what: str) -> np.ndarray:
    """(H, W, 4) float32 pixels of an image file read by Blender (rows top to bottom, as stored in
    the file), values as stored (no colour management).  Main thread only."""
    if not os.path.isfile(path):
        raise ArticulaInputError(f"{path}: {what} file missing")
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
    return np.ascontiguousarray(load_image_pixels(path, "EXR depth")[:, :, 0])


def load_color(path: str) -> np.ndarray:
    """An 8-bit colour frame (PNG/JPG) as (H, W, 3) uint8 (sRGB values as stored)."""
    px = load_image_pixels(path, "colour frame")
    return np.clip(px[:, :, :3] * 255 + 0.5, 0, 255).astype(np.uint8)
