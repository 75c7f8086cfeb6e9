"""The synthetic subjects (sample_scenes.synthetic): valid models from one skeleton builder, and tubes
whose faces close around every ring."""
import numpy as np
import pytest

from articula.sample_scenes import synthetic


@pytest.mark.parametrize("table, roll_seed", [(synthetic.HUMAN, None), (synthetic.TUBE_BODY, 0),
                                              (synthetic.TUBE_BODY, 5)])
def test_build_skeleton_gives_right_handed_frames_along_the_bones(table, roll_seed):
    sk = synthetic.build_skeleton(table, roll_seed)
    sk.validate()                                          # Y along head -> tail, det +1, parents first
    assert sk.names == [r[0] for r in table] and sk.num_bones == 19
    np.testing.assert_allclose(sk.frames.transpose(0, 2, 1) @ sk.frames, np.broadcast_to(np.eye(3), (19, 3, 3)),
                               atol=1e-12)


def test_stick_skeleton_z_axes_point_forward_and_rolls_vary_with_the_seed():
    sk = synthetic.human_skeleton()
    assert (sk.frames[:5, 1, 2] < -0.9).all()              # spine bones: Z towards -Y (the front)
    a, b = (synthetic.build_skeleton(synthetic.TUBE_BODY, s).frames for s in (0, 1))
    np.testing.assert_allclose(a[:, :, 1], b[:, :, 1])     # same Y axes, other rolls
    assert np.abs(a[:, :, 0] - b[:, :, 0]).max() > 0.1


@pytest.mark.parametrize("make", [lambda: synthetic.tube_body(rings=5, segments=7),
                                  lambda: synthetic.tube_body(rings=4, segments=6, fork_twist="all"),
                                  lambda: synthetic.random_model(100, seed=2),
                                  lambda: synthetic.tube_model(rings=6, sectors=8),
                                  lambda: synthetic.cylinder(6, 8, 0.3)])
def test_models_are_valid(make):
    make().validate()


@pytest.mark.parametrize("rings, segments", [(2, 3), (5, 7)])
def test_tube_faces_close_every_ring(rings, segments):
    faces = synthetic._tube_faces(rings, segments)
    assert faces.shape == (2 * (rings - 1) * segments, 3)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    # an open tube: ring edges at the two ends once, every other edge twice (brute-force count)
    assert (counts == 1).sum() == 2 * segments and set(counts) <= {1, 2}
