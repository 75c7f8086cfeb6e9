"""Model and Poses validation rules, each on its own: an input that breaks exactly one rule is refused
with a message naming the key, the vertex/frame and the value."""
import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.model import QUAT_RENORM_TOL, QUAT_TOL, Poses


def _fork(model):
    """A vertex whose anchor has at least two children, and two of those children."""
    sk = model.skeleton
    v = next(int(v) for v in range(model.num_vertices) if len(sk.children(int(model.anchor[v]))) >= 2)
    return v, sk.children(int(model.anchor[v]))[:2]


@pytest.mark.parametrize("key", ["twist_weights", "swing_weights"])
def test_weights_summing_above_one_on_child_bones_only_are_refused(key):
    """Every weight of the row is in [0, 1] and on a child of the anchor, so only the sum rule applies."""
    model = synthetic.random_model(60, seed=3)
    model.validate()
    v, (c1, c2) = _fork(model)
    w = getattr(model, key)
    w[v] = 0.0
    w[v, c1], w[v, c2] = 0.6, 0.55
    child = model.skeleton.child_matrix()[model.anchor[v]]
    assert child[c1] and child[c2] and (w[v] >= 0).all() and (w[v] <= 1).all()
    with pytest.raises(ArticulaInputError, match=rf"{key}: vertex {v}: weights sum to 1\.15 > 1"):
        model.validate()
    w[v, c2] = 0.4                                    # sum exactly 1: accepted
    model.validate()


def test_quaternion_norm_message_shows_enough_digits():
    p = Poses.identity(2, 3)
    p.rotations[1, 2] *= 1.0 + 3e-6                  # rounds to "1" with 6 significant digits
    with pytest.raises(ArticulaInputError, match=r"frame 1, bone 2: quaternion norm 1\.00000[0-9]+ is not 1 "
                                                 r"\(off by 3e-06") as err:
        p.validate(3)
    assert "norm 1 is not 1" not in str(err.value)


def test_near_unit_quaternions_are_normalised_with_a_note():
    p = Poses.identity(3, 4)
    p.rotations[2, 1] = [0.6, 0.8, 0.0, 0.0]
    p.rotations[2, 1] *= 1.0 + 0.5 * QUAT_RENORM_TOL      # float32-style round-off: normalised
    p.rotations[0, 3] *= 1.0 + 0.5 * QUAT_TOL             # within the strict tolerance: left alone
    kept = p.rotations[0, 3].copy()
    note = p.normalise_near_unit()
    assert "normalised 1 quaternion(s)" in note and "frame 2, bone 1" in note
    np.testing.assert_allclose(p.rotations[2, 1], [0.6, 0.8, 0.0, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(p.rotations[0, 3], kept)
    p.validate(4)
    assert p.normalise_near_unit() == ""


def test_quaternions_off_by_more_than_the_renormalising_tolerance_are_refused():
    p = Poses.identity(2, 2)
    p.rotations[1, 0] *= 1.0 + 3 * QUAT_RENORM_TOL
    assert p.normalise_near_unit() == ""
    with pytest.raises(ArticulaInputError, match=r"frame 1, bone 0: quaternion norm 1\.0003"):
        p.validate(2)


def test_poses_take_copies_the_frames_asked_for():
    p = Poses(np.tile([1.0, 0.0, 0.0, 0.0], (4, 2, 1)), np.arange(12.0).reshape(4, 3), np.arange(1.0, 5.0))
    one, some, part = p.take(2), p.take([3, 0]), p.take(slice(1, 3))
    assert len(one) == 1 and one.translations.tolist() == [[6.0, 7.0, 8.0]]
    assert some.scales.tolist() == [4.0, 1.0] and part.scales.tolist() == [2.0, 3.0]
    one.translations[0, 0] = -1.0
    assert p.translations[2, 0] == 6.0                     # a copy: the source is untouched
