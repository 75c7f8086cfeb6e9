"""Depth-camera noise model: statistics against the analytic σ(z), quantisation lattice, dropouts."""
import dataclasses

import numpy as np
import pytest

from articula.sample_scenes import depth_noise as dn
from articula.solver.errors import ArticulaInputError

PURE_AXIAL = dataclasses.replace(dn.NOISELESS, sigma_base_m=0.0012, sigma_quad_m=0.0019,
                                 sigma_angle_m=0.0001)


@pytest.mark.parametrize("z, expected_mm", [(1.0, 1.884), (3.0, 14.044)])
def test_axial_std_matches_model_head_on(z, expected_mm):
    assert dn.axial_sigma(z, 0.0) * 1000 == pytest.approx(expected_mm, abs=1e-3)
    depth = np.full((240, 320), z)
    noisy = dn.apply_noise(depth, np.ones_like(depth), np.random.default_rng(0), PURE_AXIAL)
    err = noisy - z
    assert abs(err.mean()) < 4 * expected_mm / 1000 / np.sqrt(err.size)
    assert err.std() * 1000 == pytest.approx(expected_mm, rel=0.03)


def test_angle_increases_noise():
    theta = np.radians(70.0)
    depth = np.full((200, 200), 2.0)
    cos = np.full_like(depth, np.cos(theta))
    noisy = dn.apply_noise(depth, cos, np.random.default_rng(1), PURE_AXIAL)
    expected = 0.0012 + 0.0019 * 1.6 ** 2 + 0.0001 / np.sqrt(2.0) * (70.0 / 20.0) ** 2
    assert dn.axial_sigma(2.0, theta) == pytest.approx(expected)
    assert expected > dn.axial_sigma(2.0, 0.0) * 1.1
    assert noisy.std() == pytest.approx(expected, rel=0.03)


def test_kinect_quantisation_lattice_and_step():
    p = dn.NoiseParams()
    bf = p.baseline_m * p.focal_px
    z = np.linspace(0.8, 4.0, 1000)
    q = dn.quantize(z, p)
    disparity = bf / q * p.subpixel
    np.testing.assert_allclose(disparity, np.round(disparity), atol=1e-6)   # on the 1/8 px lattice
    step_3m = np.diff(np.unique(dn.quantize(np.linspace(2.95, 3.05, 2000), p))).mean()
    assert step_3m == pytest.approx(9.0 / (8 * bf), rel=0.05)               # ~2.6 cm at 3 m
    assert np.abs(q - z).max() <= (4.0 ** 2 / (8 * bf)) / 2 * 1.05
    assert dn.quantize(np.array([0.0]), p)[0] == 0.0
    mm = dn.quantize(np.array([1.23456]), dataclasses.replace(p, quantization="mm"))
    assert mm[0] == pytest.approx(1.235)


def test_grazing_range_and_edges_drop_pixels():
    rng = np.random.default_rng(2)
    depth = np.full((60, 80), 2.0)
    depth[20:40, 30:50] = 1.0                        # a near square: depth edges around it
    depth[:, :5] = 0.0                               # empty columns
    params = dataclasses.replace(dn.NOISELESS, grazing_deg=75.0, edge_jump_m=0.05, edge_dropout=1.0,
                                 min_depth=0.5, max_depth=1.9)
    cos = np.ones_like(depth)
    cos[50:, :] = np.cos(np.radians(80.0))            # grazing rows
    out = dn.apply_noise(depth, cos, rng, params)
    edges = dn.depth_edges(depth, 0.05)
    assert not out[50:].any()                        # grazing
    assert not out[edges].any()                      # every edge pixel dropped (edge_dropout = 1)
    assert not out[:, :5].any()
    interior = np.zeros_like(edges)
    interior[22:38, 32:48] = True
    np.testing.assert_array_equal(out[interior], 1.0)
    assert not out[(depth == 2.0) & ~edges].any()    # beyond max_depth
    # the edge set: the square's rim on both sides and the border of the empty band
    assert edges[20, 35] and edges[19, 35] and not edges[25, 35] and edges[30, 5]


def test_lateral_noise_keeps_flat_surfaces_and_roughens_edges():
    params = dataclasses.replace(dn.NOISELESS, lateral_px=0.8, lateral_angle_px=0.035)
    depth = np.full((80, 80), 2.0)
    depth[:, 40:] = 1.0
    out = dn.apply_noise(depth, np.ones_like(depth), np.random.default_rng(3), params)
    assert set(np.unique(out)) == {1.0, 2.0}
    assert np.array_equal(out[:, :35], depth[:, :35]) and np.array_equal(out[:, 45:], depth[:, 45:])
    assert (out[:, 38:42] != depth[:, 38:42]).any()  # ragged boundary


def test_deterministic_from_seed_and_validation():
    depth = np.random.default_rng(9).uniform(0.5, 4.0, (50, 60))
    cos = np.full_like(depth, 0.8)
    a = dn.apply_noise(depth, cos, np.random.default_rng(5))
    b = dn.apply_noise(depth, cos, np.random.default_rng(5))
    c = dn.apply_noise(depth, cos, np.random.default_rng(6))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    with pytest.raises(ArticulaInputError, match="dropout"):
        dn.apply_noise(depth, cos, np.random.default_rng(0), dn.NoiseParams(dropout=2.0))
    with pytest.raises(ArticulaInputError, match="quantization"):
        dn.NoiseParams(quantization="disparity").validate()
    with pytest.raises(ArticulaInputError, match="does not match"):
        dn.apply_noise(depth, cos[:, 1:], np.random.default_rng(0))


def test_slope_aware_edges_keep_tilted_surfaces():
    """A plane at 70 deg incidence has large depth steps between pixels but no discontinuity."""
    f, z0 = 290.0, 2.5
    u = np.arange(200) - 99.5
    # plane tilted about the image's vertical axis: z = z0 / (1 - tan(70deg) * u / f)
    z = z0 / (1 - np.tan(np.radians(70.0)) * u / f * 0.5)
    depth = np.tile(z, (20, 1))
    depth = depth[:, (depth[0] > 0) & (depth[0] < 6)]
    steps = np.abs(np.diff(depth[0]))
    assert steps.max() > 0.03                                 # plain threshold would call these edges
    assert dn.depth_edges(depth, 0.03)[5:15, 5:-5].any()
    slope = np.tan(np.radians(78.0)) / f
    assert not dn.depth_edges(depth, 0.03, slope)[1:-1, 1:-1].any()
    step = depth.copy()
    step[:, 50:] += 0.4                                       # a real discontinuity is still found
    assert dn.depth_edges(step, 0.03, slope)[5, 49] and dn.depth_edges(step, 0.03, slope)[5, 50]


def test_quantisation_step_matches_real_kinect_frames():
    """Real Kinect v1 frames hold depth on the disparity lattice: consecutive distinct values differ
    by z^2 / (8 b f).  Measured on the Skeltrack frames: 8 b f ~ 346-348 (model: 348)."""
    import glob
    import os

    from articula.solver.formats import png16

    from ..conftest import SHARED_DATA
    files = sorted(glob.glob(os.path.join(SHARED_DATA, "depth", "skeltrack_kinect", "*.png")))
    if not files:
        pytest.skip("shared Kinect depth frames not available")
    values = np.unique(np.concatenate([png16.read_png16(f).ravel() for f in files]))
    z = values[values > 0] / 1000.0
    mid, step = (z[1:] + z[:-1]) / 2, np.diff(z)
    sel = (mid > 1.0) & (mid < 2.0)
    assert sel.sum() > 50
    p = dn.NoiseParams()
    model = p.subpixel * p.baseline_m * p.focal_px
    assert np.median(mid[sel] ** 2 / step[sel]) == pytest.approx(model, rel=0.05)
