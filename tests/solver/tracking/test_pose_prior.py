"""Pose prior (solver.tracking.pose_prior): pairs, box limits, residual Jacobians, files, the generic prior and
its mapping onto other rigs through the role vocabulary (learned rigs' role names included)."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.geometry.rotations import quat_mul, quat_to_rotvec, rotvec_to_quat
from articula.solver.rig.jacobians import pose_layout
from articula.solver.rig.model import Poses, Skeleton, frames_from_bones
from articula.solver.tracking import gmm
from articula.solver.tracking.pose_prior import (PosePrior, generic_prior, joint_pairs,
                                              rotvec_increment_jacobian)

PARENTS = [-1, 0, 1, 2, 1, 0]


def _skeleton():
    heads = np.array([[0, 0, 0], [0, 0, 0.1], [0, 0, 0.4], [0, 0, 0.7], [0.1, 0, 0.4], [0.1, 0, 0]], float)
    tails = heads + np.array([[0, 0, 0.1], [0, 0, 0.3], [0, 0, 0.3], [0, 0, 0.2], [0.3, 0, 0], [0, 0, -0.4]])
    return Skeleton(["root", "a", "b", "c", "d", "e"], PARENTS, heads, tails, frames_from_bones(heads, tails))


def _poses(n=16, seed=0):
    rng = np.random.default_rng(seed)
    r = 0.3 * rng.standard_normal((n, len(PARENTS), 3)) + np.array([0, 0.2, -0.4])
    r[:n // 2, 2] += 0.8                    # two clusters on bone b
    return Poses(rotvec_to_quat(r), np.zeros((n, 3)), np.ones(n))


@pytest.fixture(scope="module")
def prior():
    return PosePrior.from_poses(_skeleton(), _poses(), k_max=3)


def test_pairs_skip_the_root():
    np.testing.assert_array_equal(joint_pairs(PARENTS), [[1, 2], [2, 3], [1, 4]])


def test_box_limits_are_min_max(prior):
    r = quat_to_rotvec(_poses().rotations)
    np.testing.assert_array_equal(prior.lower[1:], r.min(axis=0)[1:])
    np.testing.assert_array_equal(prior.upper[1:], r.max(axis=0)[1:])
    assert np.all(np.isinf(prior.lower[0])) and np.all(np.isinf(prior.upper[0]))
    wide = PosePrior.from_poses(_skeleton(), _poses(), k_max=1, margin=0.1, sparsify=False)
    np.testing.assert_allclose(wide.upper[1:] - wide.lower[1:], 1.2 * (r.max(0) - r.min(0))[1:])


def test_box_violations(prior):
    r = np.full((6, 3), 100.0)               # the root is free
    r[1:] = 0.5 * (prior.lower[1:] + prior.upper[1:])
    r[2, 1] = prior.upper[2, 1] + 0.5
    r[3, 0] = prior.lower[3, 0] - 0.1
    bad, clamped = prior.box_violations(r)
    assert bad.sum() == 2 and bad[2, 1] and bad[3, 0]
    assert clamped[2, 1] == prior.upper[2, 1] and clamped[3, 0] == prior.lower[3, 0]
    np.testing.assert_array_equal(clamped[~bad], r[~bad])


def test_values_and_mixtures(prior):
    lik = prior.likelihoods(_poses().rotations)
    assert lik.shape == (16, 3) and np.all((lik > 0) & (lik <= 1))
    assert np.all(prior.weights.sum(axis=1) > 1 - 1e-12)
    assert gmm.is_positive_definite(prior.precisions)
    assert set(prior.components) <= {1, 2, 3}
    q = prior.value(_poses().rotations)
    assert np.all((q >= 0) & (q < 1))
    far = rotvec_to_quat(np.full((1, 6, 3), 1.5))
    assert prior.value(far)[0] > q.max()


def _fd(f, x, h=1e-6):
    cols = []
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_pair_jacobian_matches_finite_differences(prior):
    r0 = quat_to_rotvec(_poses(4, seed=3).rotations)
    for n in range(4):
        def e_of(x, n=n):
            r = r0[n].copy()
            r[1], r[2] = x[:3], x[3:]
            return prior.residuals(rotvec_to_quat(r))[0, 0]
        x0 = np.concatenate([r0[n, 1], r0[n, 2]])
        np.testing.assert_allclose(prior.pair_jacobian(rotvec_to_quat(r0[n]))[0, 0], _fd(e_of, x0),
                                   rtol=1e-5, atol=1e-8)


def test_increment_jacobian_matches_finite_differences(prior):
    q0 = _poses(1, seed=4).rotations[0]
    layout = pose_layout(6)
    J = prior.jacobian(q0)[0]
    for b in range(6):
        def e_of(d, b=b):
            q = q0.copy()
            q[b] = quat_mul(q0[b], rotvec_to_quat(d))
            return prior.residuals(q)[0]
        np.testing.assert_allclose(J[:, layout["rotation"](b)], _fd(e_of, np.zeros(3)), rtol=1e-5, atol=1e-8)
    assert np.all(J[:, :4] == 0)


@pytest.mark.parametrize("angle", [0.0, 1e-6, 0.5, 2.0, 3.1])
def test_rotvec_increment_jacobian(angle):
    r = angle * np.array([0.48, -0.6, 0.64])
    q = rotvec_to_quat(r)
    fd = _fd(lambda d: quat_to_rotvec(quat_mul(q, rotvec_to_quat(d))), np.zeros(3))
    np.testing.assert_allclose(rotvec_increment_jacobian(r), fd, atol=1e-6)


def test_save_load_round_trip(prior, tmp_path):
    path = tmp_path / "prior.npz"
    prior.save(path)
    back = PosePrior.load(path)
    for key in ("frames", "pairs", "weights", "means", "precisions", "lower", "upper", "components", "loo_scores"):
        np.testing.assert_array_equal(getattr(back, key), getattr(prior, key))
    assert back.names == prior.names and back.info == prior.info and back.enabled
    q = _poses(3, seed=9).rotations
    np.testing.assert_array_equal(back.residuals(q), prior.residuals(q))


def test_broken_files(prior, tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip at all")
    with pytest.raises(ArticulaInputError, match="junk.npz: not a readable pose-prior"):
        PosePrior.load(junk)
    other = tmp_path / "other.npz"
    np.savez(other, format=np.array("articula-model/1"))
    with pytest.raises(ArticulaInputError, match="format key is 'articula-model/1'"):
        PosePrior.load(other)
    cut = tmp_path / "cut.npz"
    prior.save(cut)
    with np.load(cut) as z:
        data = {k: z[k] for k in z.files if k != "means"}
    np.savez(cut, **data)
    with pytest.raises(ArticulaInputError, match="missing key.*means"):
        PosePrior.load(cut)


def test_switched_off_and_too_few_poses():
    off = PosePrior.none(_skeleton())
    q = _poses(2).rotations
    assert off.residuals(q).shape == (2, 0) and np.all(off.value(q) == 0) and off.jacobian(q).shape == (2, 0, 22)
    bad, clamped = off.box_violations(np.full((6, 3), 9.0))
    assert not bad.any() and np.all(clamped == 9.0)
    with pytest.raises(ArticulaInputError, match="2 training pose.*generic"):
        PosePrior.from_poses(_skeleton(), _poses(2))


@pytest.fixture(scope="module")
def cmu_subject():
    from articula.sample_scenes.subjects import make_subject
    return make_subject("cmu_mb", "female,heavy")


def _knee_backwards(subject, q, degrees=150.0):
    """``q`` (B, 4) with the left knee bent backwards (against its flexion) by ``degrees``."""
    from articula.sample_scenes.bone_roles import hinge_geometry, skeleton_roles
    axes, _ = hinge_geometry(subject.skeleton, skeleton_roles(subject.skeleton.names))
    knee = subject.skeleton.names.index("Leg.L")
    q = q.copy()
    q[knee] = rotvec_to_quat(-np.radians(degrees) * axes[knee])
    return q, knee


def test_generic_prior_likes_a_walk_and_refuses_a_backward_knee(cmu_subject):
    from articula.sample_scenes.walk import walk_poses
    prior = generic_prior(cmu_subject.skeleton)
    assert prior.info["licence"].startswith("CC0") and prior.info["rig"] == "cmu_mb"
    assert prior.num_pairs == len(joint_pairs(cmu_subject.skeleton.parents))
    walk = walk_poses(cmu_subject, 1, seed=123).rotations[0]
    absurd, knee = _knee_backwards(cmu_subject, walk)
    knee_pairs = [p for p, (a, c) in enumerate(prior.pairs) if knee in (a, c)]
    good, bad = prior.likelihoods(walk)[0], prior.likelihoods(absurd)[0]
    assert good[knee_pairs].min() > 0.01 and bad[knee_pairs].max() < 1e-6
    assert prior.value(walk)[0] < prior.value(absurd)[0]
    violated, _ = prior.box_violations(quat_to_rotvec(absurd))
    assert violated[knee].any() and not prior.box_violations(quat_to_rotvec(walk))[0][knee].any()


def test_generic_prior_maps_mpfb_names_and_skips_unknown_bones(cmu_subject):
    sk = cmu_subject.skeleton
    renamed = Skeleton(list(cmu_subject.source_names), sk.parents, sk.heads, sk.tails, sk.frames)
    a, b = generic_prior(sk), generic_prior(renamed)
    np.testing.assert_array_equal(a.pairs, b.pairs)
    np.testing.assert_allclose(a.means, b.means)
    odd = Skeleton([n if not n.startswith("Leg") else "shin_" + n for n in sk.names], sk.parents, sk.heads,
                   sk.tails, sk.frames)
    c = generic_prior(odd)
    legs = [i for i, n in enumerate(odd.names) if n.startswith("shin_")]
    assert c.num_pairs == a.num_pairs - 4 and not np.isin(c.pairs, legs).any()
    assert np.all(np.isinf(c.lower[legs]))


def test_widened_box_is_the_hull_padded(prior):
    """``widened``: the hull of the prior's box and another's finite bounds, then ``pad`` on each side;
    the mixtures are untouched; a negative or infinite pad is refused."""
    from articula.solver.tracking.pose_prior import widened
    other = PosePrior.from_poses(_skeleton(), _poses(seed=3), k_max=1, sparsify=False)
    other.lower[4], other.upper[4] = -np.inf, np.inf                 # a bone the other prior does not bound
    out = widened(prior, other, pad=0.05)
    np.testing.assert_array_equal(out.lower[1:4], np.minimum(prior.lower, other.lower)[1:4] - 0.05)
    np.testing.assert_array_equal(out.upper[5], np.maximum(prior.upper, other.upper)[5] + 0.05)
    np.testing.assert_array_equal(out.lower[4], prior.lower[4] - 0.05)
    assert np.all(np.isinf(out.lower[0])) and out.means is prior.means and "pad 0.05" in out.info["box"]
    np.testing.assert_array_equal(widened(prior).lower, prior.lower)
    for bad in (-0.1, np.inf):
        with pytest.raises(ArticulaInputError, match="pad"):
            widened(prior, pad=bad)


def test_generic_prior_on_a_child_bone_named_like_its_root(cmu_subject):
    """A rig whose ``Hips`` is a child of another root (the generic prior's root is unbounded) gets no
    bound on that bone, not NaN bounds: the rest pose violates nothing and clamping keeps it finite."""
    sk = cmu_subject.skeleton
    heads = np.vstack([sk.heads[:1] - [0, 0, 0.1], sk.heads])
    tails = np.vstack([sk.heads[:1], sk.tails])
    rooted = Skeleton(["Root", *sk.names], np.concatenate([[-1], sk.parents + 1]), heads, tails,
                      np.concatenate([frames_from_bones(heads[:1], tails[:1]), sk.frames]))
    prior = generic_prior(rooted)
    assert not np.isnan(prior.lower).any() and not np.isnan(prior.upper).any()
    assert np.all(np.isinf(prior.lower[1])) and np.all(np.isinf(prior.upper[1]))
    np.testing.assert_array_equal(prior.lower[2:], generic_prior(sk).lower[1:])
    violated, clamped = prior.box_violations(np.zeros((rooted.num_bones, 3)))
    assert not violated.any() and np.isfinite(clamped).all()


def _learned_names(skeleton):
    """``skeleton`` with the bone names learn_rig gives a humanoid (solver.learn.role_names, from the
    geometry alone: roles, ``part_NN`` for the rest)."""
    from articula.solver.learn.role_names import role_names
    parts = Skeleton([f"part_{b:02d}" for b in range(skeleton.num_bones)], skeleton.parents, skeleton.heads,
                     skeleton.tails, skeleton.frames)
    return Skeleton(role_names(parts), skeleton.parents, skeleton.heads, skeleton.tails, skeleton.frames)


def test_generic_prior_reaches_a_learned_rigs_role_names(cmu_subject):
    """On the cmu_mb body renamed as learn_rig names it, the generic prior has the mixtures of the rig's
    own names on the upper arm, shin, toe and chest pairs (same bones, same rest frames)."""
    sk = cmu_subject.skeleton
    learned = _learned_names(sk)
    truth, mapped = generic_prior(sk), generic_prior(learned)
    want = {"upper_arm.L", "upper_arm.R", "shin.L", "shin.R", "toe.L", "chest"}
    pairs = {(learned.names[a], learned.names[c]): p for p, (a, c) in enumerate(mapped.pairs)}
    roles = {name for pair in pairs for name in pair}
    assert want <= roles and ("upper_arm.L", "forearm.L") in pairs and ("thigh.R", "shin.R") in pairs
    assert ("chest", "neck") in pairs and ("shin.L", "foot.L") in pairs and ("foot.L", "toe.L") in pairs
    same = {tuple(ac): p for p, ac in enumerate(truth.pairs.tolist())}
    for (a, c), p in pairs.items():
        q = same[(learned.names.index(a), learned.names.index(c))]
        k = int(truth.components[q])
        np.testing.assert_allclose(mapped.means[p, :k], truth.means[q, :k], atol=1e-12)
        np.testing.assert_allclose(mapped.precisions[p, :k], truth.precisions[q, :k], rtol=1e-9)
    assert mapped.num_pairs >= 15                                   # 17 of 27: fingers are part_NN
    bounded = [learned.names.index(r) for r in want]
    np.testing.assert_allclose(mapped.lower[bounded], truth.lower[bounded])


@pytest.mark.parametrize("rig", ["game_engine", "mixamo"])
def test_generic_prior_on_other_mpfb_rigs_by_role(rig):
    """The generic (cmu_mb) prior reaches the limb pairs of rigs named otherwise (calf, lowerarm, Leg…)."""
    from articula.sample_scenes.subjects import make_subject
    from articula.solver.roles import bone_roles
    sk = make_subject(rig).skeleton
    prior = generic_prior(sk)
    roles = bone_roles(sk.names)
    pairs = {(roles[a], roles[c]) for a, c in prior.pairs}
    for side in "LR":
        assert {(f"upper_arm.{side}", f"forearm.{side}"), (f"thigh.{side}", f"shin.{side}"),
                (f"shin.{side}", f"foot.{side}"), (f"foot.{side}", f"toe.{side}")} <= pairs
