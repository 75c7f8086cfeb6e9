"""Blender F-curves as stored in MPFB2 animation JSON (``walkcycles/*.json``), evaluated with numpy.

File layout: ``{"animation_data": {bone: {frame: {channel: {"values": [v0, v1, v2],
"metadata": [{"handle_left": [f, v], "handle_right": [f, v], "interpolation": "BEZIER"|"LINEAR"|
"CONSTANT", ...} per component]}}}}, "metadata": {...}}`` with channel ``rotation_euler`` (radians,
Blender's XYZ Euler: R = Rz Ry Rx, in the bone's local rest axes), ``location`` (rest-relative, bone
axes) or ``scale``.  A segment between keys k and k+1 is Blender's cubic Bezier through
(frame_k, v_k), handle_right_k, handle_left_{k+1}, (frame_{k+1}, v_{k+1}); the curve parameter for a
frame is found by bisection on the (monotonic) frame polynomial.  Before the first / after the last
key the curve is constant.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..solver.errors import ArticulaInputError


@dataclass(frozen=True)
class FCurve:
    """One animated scalar: key frames (K,), values (K,), handles (K, 2, 2) [left/right][frame, value]."""
    frames: np.ndarray
    values: np.ndarray
    handles: np.ndarray
    interpolation: tuple

    def __call__(self, frames) -> np.ndarray:
        """Values at ``frames`` (any shape)."""
        x = np.asarray(frames, dtype=np.float64)
        if len(self.frames) == 1:
            return np.full(x.shape, self.values[0])
        xc = np.clip(x, self.frames[0], self.frames[-1])
        seg = np.clip(np.searchsorted(self.frames, xc, side="right") - 1, 0, len(self.frames) - 2)
        return self._segment_values(seg, xc)

    def _segment_values(self, seg, x):
        f0, f1 = self.frames[seg], self.frames[seg + 1]
        v0, v1 = self.values[seg], self.values[seg + 1]
        linear = v0 + (v1 - v0) * (x - f0) / (f1 - f0)
        px = np.stack([f0, self.handles[seg, 1, 0], self.handles[seg + 1, 0, 0], f1])
        py = np.stack([v0, self.handles[seg, 1, 1], self.handles[seg + 1, 0, 1], v1])
        t = _solve_bezier_parameter(px, x)
        bez = _bezier(py, t)
        kind = np.array(self.interpolation)[seg]
        return np.where(kind == "BEZIER", bez, np.where(kind == "LINEAR", linear, v0))


def _bezier(p, t):
    """Cubic Bezier with control values p (4, ...) at parameters t (...)."""
    s = 1 - t
    return s ** 3 * p[0] + 3 * s * s * t * p[1] + 3 * s * t * t * p[2] + t ** 3 * p[3]


def _solve_bezier_parameter(px, x, iterations=40):
    """t in [0, 1] with Bezier_x(t) = x (px (4, ...) non-decreasing in t): bisection."""
    lo, hi = np.zeros_like(x), np.ones_like(x)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        below = _bezier(px, mid) < x
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def channel_curves(bone_keys: dict, channel: str, name: str = "") -> list | None:
    """The three :class:`FCurve` of ``channel`` of one bone (``{frame: {channel: ...}}``), or None."""
    keys = sorted((float(f), data[channel]) for f, data in bone_keys.items() if channel in data)
    if not keys:
        return None
    curves = []
    for c in range(len(keys[0][1]["values"])):
        try:
            meta = [k[1]["metadata"][c] for k in keys]
            curves.append(FCurve(np.array([k[0] for k in keys]), np.array([k[1]["values"][c] for k in keys]),
                                 np.array([[m["handle_left"], m["handle_right"]] for m in meta], dtype=float),
                                 tuple(m.get("interpolation", "BEZIER") for m in meta)))
        except (KeyError, IndexError, TypeError) as exc:
            raise ArticulaInputError(f"{name}: channel {channel!r} has a malformed key ({exc})") from None
    return curves


def evaluate(curves: list, frames) -> np.ndarray:
    """(N, C) values of C curves at frames (N,)."""
    return np.stack([c(frames) for c in curves], axis=-1)


def euler_xyz_to_matrix(e: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of Blender XYZ Euler angles (..., 3): R = Rz(z) Ry(y) Rx(x)."""
    cx, cy, cz = np.cos(e[..., 0]), np.cos(e[..., 1]), np.cos(e[..., 2])
    sx, sy, sz = np.sin(e[..., 0]), np.sin(e[..., 1]), np.sin(e[..., 2])
    R = np.empty(e.shape[:-1] + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = cy * cz, sx * sy * cz - cx * sz, cx * sy * cz + sx * sz
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = cy * sz, sx * sy * sz + cx * cz, cx * sy * sz - sx * cz
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = -sy, sx * cy, cx * cy
    return R
