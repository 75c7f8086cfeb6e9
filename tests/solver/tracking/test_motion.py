"""The shared prediction of the next pose against closed forms: constant angular velocity about fixed
axes and a constant drift are carried on exactly; ``carry`` scales the turn's angle and the drift."""
import numpy as np

from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.model import Poses
from articula.solver.tracking.motion import extrapolate


def _at(k, axes, rate):
    """Frame k of bones turning at ``rate`` rad per frame about their ``axes`` (B, 3), drifting 1 cm."""
    return Poses(rotvec_to_quat(k * rate * axes)[None], np.array([[0.01 * k, 0.0, 0.0]]), np.ones(1))


def test_constant_turn_and_drift_are_carried_on_exactly():
    axes = np.random.default_rng(0).normal(size=(6, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    p = extrapolate(_at(1, axes, 0.3), _at(2, axes, 0.3))
    truth = _at(3, axes, 0.3)
    assert np.allclose(quat_to_rotvec(p.rotations), quat_to_rotvec(truth.rotations))
    assert np.allclose(p.translations, truth.translations)
    half = extrapolate(_at(1, axes, 0.3), _at(2, axes, 0.3), 0.5)
    assert np.allclose(quat_to_rotvec(half.rotations), 2.5 * 0.3 * axes[None])
    assert np.allclose(half.translations, [[0.025, 0.0, 0.0]])
    still = extrapolate(_at(1, axes, 0.3), _at(2, axes, 0.3), 0.0)
    assert np.allclose(still.rotations, _at(2, axes, 0.3).rotations)
