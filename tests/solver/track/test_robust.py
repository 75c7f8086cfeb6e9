"""Charbonnier norm and IRLS weights (model-adaptive mocap dissertation Eq. 4.4-4.6)."""
import numpy as np

from articula.solver.track import robust


def test_formula_and_values():
    e = np.array([[0.0, 0.0, 0.0], [0.003, 0.004, 0.0], [1.0, 0.0, 0.0]])
    rho = robust.charbonnier(e, eps=1e-3)
    np.testing.assert_allclose(rho, [1e-3, np.sqrt(0.005 ** 2 + 1e-6), np.sqrt(1 + 1e-6)])
    np.testing.assert_allclose(robust.irls_weights(e, eps=1e-3), 1 / rho)
    np.testing.assert_allclose(robust.data_energy(e, eps=1e-3), rho.mean())
    assert robust.data_energy(np.zeros((0, 3))) == 0.0


def test_weights_are_clamped_for_tiny_eps():
    w = robust.irls_weights(np.array([0.0, 1e-7, 0.01]), eps=1e-9)
    np.testing.assert_allclose(w, [1 / robust.FLOOR_M, 1 / robust.FLOOR_M, 100.0], rtol=1e-9)


def test_irls_converges_to_the_median_in_1d():
    x = np.array([0.0, 0.01, 0.02, 0.03, 5.0])       # one gross outlier
    m = x.mean()
    for _ in range(200):
        w = robust.irls_weights(x - m, eps=1e-6)
        m = (w * x).sum() / w.sum()
    assert abs(m - np.median(x)) < 1e-4
