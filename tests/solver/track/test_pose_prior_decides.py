"""The pose prior's effect on a fit (solver.track.frame_fit with solver.tracking.pose_prior), not only its
gradient: a twist of a round tube's last bone moves its vertices within the tube's surface, so the capture
barely sees it (from an untwisted start the data alone leaves it there; from the box's edge it stops
0.04 rad short); the prior learned from poses that all twist the hand by about 0.5 rad decides the fitted
twist, against the true pose the capture was made from."""
import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.track import frame_fit as ff
from articula.solver.tracking.pose_prior import PosePrior
from articula.solver.geometry.normals import vertex_normals

TWIST = 0.5        # radians about the hand's own axis (bone-local +Y)


def _twisted_hand_poses(sk, hand, spread):
    """40 training rotation vectors (40, B, 3): small random bends, the hand twisted by TWIST +- ``spread``."""
    rng = np.random.default_rng(0)
    train = rng.normal(scale=0.05, size=(40, sk.num_bones, 3))
    train[:, 0] = 0.0
    train[:, hand] = [0.0, TWIST, 0.0] + rng.normal(scale=spread, size=(40, 3))
    return train


def _with_hand_twist(r, hand, twist):
    """One-frame Poses of rotation vectors ``r`` (B, 3) with the hand's twist set to ``twist`` radians."""
    r = r.copy()
    r[hand] = [0.0, twist, 0.0]
    return Poses(rotvec_to_quat(r)[None], np.zeros((1, 3)), np.ones(1))


@pytest.fixture(scope="module")
def hand_twist():
    """(model, hand bone, prior, true pose, start pose with the hand untwisted)."""
    model = synthetic.tube_body()
    sk = model.skeleton
    B, hand = sk.num_bones, sk.names.index("hand.L")
    train = _twisted_hand_poses(sk, hand, 0.05)
    # margin 1: the box (0.25..0.74 rad of twist) leaves the mixture to find the twist inside it
    prior = PosePrior.from_poses(sk, Poses(rotvec_to_quat(train), np.zeros((40, 3)), np.ones(40)), k_max=1,
                                 margin=1.0)
    r = np.random.default_rng(5).normal(scale=0.05, size=(B, 3))
    r[0] = 0.0
    truth, start = _with_hand_twist(r, hand, TWIST), _with_hand_twist(r, hand, 0.0)
    return model, hand, prior, truth, start


def _fit(model, truth, start, prior):
    posed = hybrid_skin(model, truth)[0]
    capture = ff.Capture(posed, vertex_normals(posed, model.faces))
    return ff.fit_frame(model, capture, start, prior), posed


def test_the_prior_restores_a_twist_the_capture_barely_sees(hand_twist):
    model, hand, prior, truth, start = hand_twist
    out, posed = _fit(model, truth, start, prior)
    twist = quat_to_rotvec(out.pose.rotations[0, hand])[1]
    on_hand = np.asarray(model.anchor) == hand
    error = np.linalg.norm(hybrid_skin(model, out.pose)[0] - posed, axis=1)[on_hand].mean()
    assert abs(twist - TWIST) < 0.02
    assert error < 0.001


def test_without_the_prior_the_twist_stays_where_it_started(hand_twist):
    """The same fit without a prior: the capture leaves the twist where the start had it (the case above is
    decided by the prior, not by the data)."""
    model, hand, _, truth, start = hand_twist
    out, _ = _fit(model, truth, start, None)
    assert abs(quat_to_rotvec(out.pose.rotations[0, hand])[1]) < 0.05


def test_the_tracker_uses_the_models_own_prior():
    """The whole tracker (``pipeline.track_sequence`` with ``prior="model"``, the prior learned from the
    model's poses whose hand twists by 0.5 +- 0.15 rad) from a start twisted by 0.2 on a capture that does
    not see the hand nor the skin its twist blends into (so the twist is up to the prior): the twist goes most of the way to the prior's 0.5 (the
    searched frame's fit stops on its step, not at the prior's minimum); with ``prior="none"`` it stays at 0.2."""
    from articula.solver.track import pipeline
    from articula.solver.track.options import TrackOptions
    model = synthetic.tube_body()
    sk = model.skeleton
    B, hand = sk.num_bones, sk.names.index("hand.L")
    train = _twisted_hand_poses(sk, hand, 0.15)
    poses = Poses(rotvec_to_quat(train), np.zeros((40, 3)), np.ones(40))
    r = np.random.default_rng(5).normal(scale=0.05, size=(B, 3))
    r[0] = 0.0
    posed = hybrid_skin(model, _with_hand_twist(r, hand, TWIST))[0]
    start = _with_hand_twist(r, hand, 0.2)
    seen = (model.anchor != hand) & (model.twist_weights[:, hand] == 0) & (model.swing_weights[:, hand] == 0)
    captures = [ff.Capture(posed[seen], vertex_normals(posed, model.faces)[seen])]
    twist = {}
    for prior in ("model", "none"):
        res = pipeline.track_sequence(model, captures, TrackOptions(prior=prior, temporal=False, max_points=0),
                                      poses, start_pose=start)
        twist[prior] = quat_to_rotvec(res.poses.rotations[0, hand])[1]
    assert twist["model"] - 0.2 > 0.5 * (TWIST - 0.2) and twist["model"] < TWIST + 0.02
    assert abs(twist["none"] - 0.2) < 0.02
