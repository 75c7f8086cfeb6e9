"""Depth-camera noise model for synthetic recordings (Kinect v1 style structured light).

Applied to a noise-free rendered depth image (metres, 0 = nothing) together with the incidence
angle θ between surface normal and viewing ray (``depth_render.incidence_cosine``):

1. **Lateral noise**: every pixel takes the clean depth of a pixel displaced by N(0, σ_L) in u and
   v (rounded), σ_L = 0.8 px + 0.035 px · θ/(π/2 − θ)  [Nguyen, Izadi & Lovell, "Modeling Kinect
   sensor noise for improved 3D reconstruction and tracking", 3DIMPVT 2012, Eq. 1].  Ragged edges.
2. **Axial noise**: Gaussian, σ_z(z, θ) = 1.2 mm + 1.9 mm/m² · (z − 0.4 m)² + 0.1 mm·m^½ / √z ·
   θ²/(π/2 − θ)²  [same paper, Eq. 2; fitted for 0.5–3 m, θ < ~70°].  σ(1 m) ≈ 1.9 mm,
   σ(3 m) ≈ 14 mm, matching Khoshelham & Elberink (Sensors 2012): "a few mm up to about 4 cm at 5 m".
3. **Quantisation**: Kinect v1 reports disparity in 1/8 pixel steps (Konolige & Mihelich,
   "Technical description of Kinect calibration", ROS wiki): z = b·f/d with baseline b = 7.5 cm and
   f = 580 px, so the depth step is z²/(8·b·f) ≈ 2.9 mm at 1 m and 2.6 cm at 3 m.  ``"mm"`` rounds to
   millimetres only (ToF cameras); the PNG writer always rounds to millimetres anyway.
4. **Missing pixels**: outside the working range (``min_depth``..``max_depth``), at grazing angles
   (θ > ``grazing_deg``), at depth discontinuities of the clean image (pixels with a 4-neighbour
   further away than a continuous surface at the grazing limit could be, ``edge_jump_m +
   z·tan(grazing)/f``, are dropped with probability ``edge_dropout``), plus uniform random dropout.

All randomness comes from the ``numpy.random.Generator`` passed in (deterministic from a seed).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..solver.errors import ArticulaInputError


@dataclass(frozen=True)
class NoiseParams:
    """Parameters of :func:`apply_noise` (metres, pixels, degrees).  Defaults: Kinect v1."""

    sigma_base_m: float = 0.0012      # axial σ at z0 (head-on)
    sigma_quad_m: float = 0.0019      # growth, σ += sigma_quad · (z − z0)² (z in m)
    sigma_z0_m: float = 0.4
    sigma_angle_m: float = 0.0001     # angular term coefficient (metres·√m)
    lateral_px: float = 0.8           # lateral σ (pixels) head-on; 0 disables lateral noise
    lateral_angle_px: float = 0.035
    quantization: str = "kinect_v1"   # "kinect_v1" (disparity 1/8 px), "mm", or "none"
    baseline_m: float = 0.075
    focal_px: float = 580.0           # of the native 640x480 sensor (independent of output size)
    subpixel: float = 8.0
    min_depth: float = 0.4
    max_depth: float = 4.5
    grazing_deg: float = 78.0
    edge_jump_m: float = 0.03
    edge_dropout: float = 0.5
    dropout: float = 0.002

    def validate(self) -> "NoiseParams":
        for key in ("sigma_base_m", "sigma_quad_m", "sigma_angle_m", "lateral_px", "lateral_angle_px",
                    "edge_jump_m", "min_depth"):
            if not getattr(self, key) >= 0:
                raise ArticulaInputError(f"noise parameter {key} must be >= 0, got {getattr(self, key)!r}")
        for key in ("edge_dropout", "dropout"):
            if not 0 <= getattr(self, key) <= 1:
                raise ArticulaInputError(f"noise parameter {key} must be in [0, 1], got {getattr(self, key)!r}")
        if not self.max_depth > self.min_depth:
            raise ArticulaInputError(f"noise parameters: max_depth {self.max_depth} <= min_depth {self.min_depth}")
        if not 0 < self.grazing_deg <= 90:
            raise ArticulaInputError(f"noise parameter grazing_deg must be in (0, 90], got {self.grazing_deg!r}")
        if self.quantization not in ("kinect_v1", "mm", "none"):
            raise ArticulaInputError(f"noise parameter quantization must be 'kinect_v1', 'mm' or 'none', "
                                     f"got {self.quantization!r}")
        if self.quantization == "kinect_v1" and not (self.baseline_m > 0 and self.focal_px > 0 and self.subpixel > 0):
            raise ArticulaInputError("noise parameters: baseline_m, focal_px and subpixel must be positive")
        return self


NOISELESS = NoiseParams(sigma_base_m=0, sigma_quad_m=0, sigma_angle_m=0, lateral_px=0, lateral_angle_px=0,
                        quantization="none", min_depth=0, max_depth=1e9, grazing_deg=90,
                        edge_dropout=0, dropout=0)


def _angle_ratio(theta):
    """θ/(π/2 − θ), finite (capped) at grazing incidence."""
    return theta / np.maximum(np.pi / 2 - theta, 1e-3)


def axial_sigma(z, theta, params: NoiseParams = NoiseParams()):
    """Axial (depth) noise σ in metres at depth z (m) and incidence angle θ (radians)."""
    z = np.asarray(z, dtype=float)
    angular = params.sigma_angle_m / np.sqrt(np.maximum(z, 1e-6)) * _angle_ratio(theta) ** 2
    return params.sigma_base_m + params.sigma_quad_m * (z - params.sigma_z0_m) ** 2 + angular


def lateral_sigma(theta, params: NoiseParams = NoiseParams()):
    """Lateral noise σ in pixels at incidence angle θ (radians)."""
    return params.lateral_px + params.lateral_angle_px * _angle_ratio(theta)


def quantize(z, params: NoiseParams = NoiseParams()):
    """Depth quantisation of the chosen sensor model (metres in, metres out; 0 stays 0)."""
    z = np.asarray(z, dtype=float)
    if params.quantization == "none":
        return z.copy()
    if params.quantization == "mm":
        return np.round(z * 1000.0) / 1000.0
    bf = params.baseline_m * params.focal_px
    with np.errstate(divide="ignore"):
        disparity = np.round(bf / z * params.subpixel) / params.subpixel
        return np.where((z > 0) & (disparity > 0), bf / np.where(disparity > 0, disparity, 1.0), 0.0)


def depth_edges(depth, jump_m, slope_per_m=0.0):
    """(H, W) bool: valid pixels with a 4-neighbour whose depth differs by more than
    ``jump_m + slope_per_m * z`` (a missing neighbour counts as a jump).

    ``slope_per_m = tan(θ_max) / f`` lets continuous surfaces up to incidence θ_max through (their
    neighbouring pixels differ by about z·tanθ/f)."""
    d = np.pad(depth, 1, constant_values=0.0)
    centre = d[1:-1, 1:-1]
    limit = jump_m + slope_per_m * centre
    edge = np.zeros(depth.shape, bool)
    for nb in (d[:-2, 1:-1], d[2:, 1:-1], d[1:-1, :-2], d[1:-1, 2:]):
        edge |= np.abs(nb - centre) > limit
    return edge & (centre > 0)


def apply_noise(depth, cos_incidence, rng: np.random.Generator, params: NoiseParams = NoiseParams(),
                focal_px: float | None = None):
    """Noisy copy of a clean depth image.

    ``depth``: (H, W) metres, 0 = nothing; ``cos_incidence``: (H, W) |cos θ| (see module docstring);
    ``rng``: the only source of randomness; ``focal_px``: the image's focal length in pixels, which
    makes the edge test slope-aware (None: plain ``edge_jump_m`` threshold).
    Returns (H, W) float64 metres, 0 = missing.
    """
    params.validate()
    depth = np.asarray(depth, dtype=float)
    if np.shape(cos_incidence) != depth.shape:
        raise ArticulaInputError(f"apply_noise: incidence image {np.shape(cos_incidence)} does not match "
                                 f"depth {depth.shape}")
    theta = np.arccos(np.clip(cos_incidence, 0.0, 1.0))
    slope = np.tan(np.radians(min(params.grazing_deg, 89.0))) / focal_px if focal_px else 0.0
    edges = depth_edges(depth, params.edge_jump_m, slope)
    z, theta = _lateral_jitter(depth, theta, rng, params)
    valid = z > 0
    noisy = z + rng.standard_normal(z.shape) * axial_sigma(z, theta, params)
    noisy = np.where(valid & (noisy > 0), quantize(noisy, params), 0.0)
    drop = ~valid | (noisy < params.min_depth) | (noisy > params.max_depth)
    drop |= theta > np.radians(params.grazing_deg)
    drop |= edges & (rng.random(z.shape) < params.edge_dropout)
    drop |= rng.random(z.shape) < params.dropout
    return np.where(drop, 0.0, noisy)


def _lateral_jitter(depth, theta, rng, params):
    """Resample depth (and θ) at pixel positions displaced by rounded N(0, σ_L(θ)) offsets
    (σ_L capped at 3 px; empty pixels use the head-on σ_L)."""
    if params.lateral_px == 0 and params.lateral_angle_px == 0:
        return depth, theta
    height, width = depth.shape
    sigma = np.minimum(lateral_sigma(np.where(depth > 0, theta, 0.0), params), 3.0)
    du = np.rint(rng.standard_normal(depth.shape) * sigma).astype(np.int64)
    dv = np.rint(rng.standard_normal(depth.shape) * sigma).astype(np.int64)
    rows = np.clip(np.arange(height)[:, None] + dv, 0, height - 1)
    cols = np.clip(np.arange(width)[None, :] + du, 0, width - 1)
    return depth[rows, cols], theta[rows, cols]
