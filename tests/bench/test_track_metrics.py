"""The tracking bench's error measures (bench/_track_metrics.py) on tiny cases with known answers: the body /
extremity split, the world rotations and their round trip through the poses, the joint regressor, the
surface distance against brute force."""
import numpy as np
import pytest

from articula.bench import _track_metrics as tm
from articula.sample_scenes.synthetic import random_model, random_poses
from articula.solver.geometry.surface_distance import closest_points_on_triangles
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import hybrid_skin

# name, parent: hands with fingers, feet with toes and the head with what hangs from it are extremities
TINY = [("root", -1), ("spine", 0), ("neck", 1), ("head", 2), ("eye.L", 3), ("upperarm.L", 1),
        ("forearm.L", 5), ("hand.L", 6), ("index1.L", 7), ("thigh.L", 0), ("calf.L", 9), ("foot.L", 10),
        ("toe.L", 11)]
TINY_EXTREMITIES = {"head", "eye.L", "hand.L", "index1.L", "foot.L", "toe.L"}


def test_extremity_bones_are_hands_feet_head_and_everything_below_them():
    names, parents = [n for n, _ in TINY], [p for _, p in TINY]
    got = tm.extremity_bones(names, parents)
    assert {n for n, e in zip(names, got) if e} == TINY_EXTREMITIES


def test_body_and_extremity_means_split_vertices_by_their_largest_weight():
    names, parents = [n for n, _ in TINY], [p for _, p in TINY]
    rng = np.random.default_rng(0)
    V, B = 40, len(names)
    dominant = rng.integers(0, B, V)
    weights = rng.uniform(0, 0.3, (V, B))
    weights[np.arange(V), dominant] = 0.9
    mask = tm.extremity_vertices(weights, names, parents)
    assert [bool(m) for m in mask] == [names[b] in TINY_EXTREMITIES for b in dominant]
    errors = rng.uniform(0, 1, (3, V))
    got = tm.split_means(errors, mask)
    for f in range(3):
        body = [errors[f, v] for v in range(V) if names[dominant[v]] not in TINY_EXTREMITIES]
        ext = [errors[f, v] for v in range(V) if names[dominant[v]] in TINY_EXTREMITIES]
        assert got["body"][f] == pytest.approx(sum(body) / len(body))
        assert got["extremities"][f] == pytest.approx(sum(ext) / len(ext))
        assert got["all"][f] == pytest.approx(errors[f].mean())


def test_worlds_are_rotations_with_the_named_up_axis():
    for R in tm.WORLDS.values():
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(tm.WORLDS["yup"] @ [0, 0, 1], [0, 1, 0])
    up = tm.WORLDS["tilt30"] @ [0, 0, 1]
    assert np.degrees(np.arccos(up[2])) == pytest.approx(30.0)


@pytest.mark.parametrize("world", sorted(tm.WORLDS))
def test_rotated_poses_pose_the_model_as_the_rotated_truth_and_back(world):
    model = random_model(300, seed=1)
    p = random_poses(4, model.skeleton.num_bones, seed=2)
    rng = np.random.default_rng(3)
    poses = Poses(p.rotations, rng.normal(scale=0.3, size=(4, 3)), rng.uniform(0.8, 1.2, 4))
    R = tm.WORLDS[world] @ tm._rotation([0.3, -1.0, 0.2], 50.0)     # a rotation with no special axis
    truth = hybrid_skin(model, poses)
    turned = tm.rotated_poses(model.skeleton, poses, R)
    assert np.abs(hybrid_skin(model, turned) - tm.rotate_points(R, truth)).max() < 1e-9
    back = tm.rotated_poses(model.skeleton, turned, R.T)
    assert np.abs(hybrid_skin(model, back) - truth).max() < 1e-9
    # errors measured in the rotated world are those of the original world
    noisy = truth + rng.normal(scale=0.01, size=truth.shape)
    assert np.allclose(tm.vertex_errors(tm.rotate_points(R, noisy), tm.rotate_points(R, truth)),
                       tm.vertex_errors(noisy, truth))


def test_rotated_cameras_see_the_rotated_world_as_before():
    R = tm.WORLDS["tilt30"]
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = tm._rotation([0, 0, 1], 40.0), [2.0, -1.0, 1.2]
    [(turned, intr)] = tm.rotate_cameras(R, [(c2w, "intrinsics")])
    x = np.array([0.3, 0.1, 1.0, 1.0])
    assert intr == "intrinsics"
    assert np.allclose(np.linalg.solve(turned, np.r_[R @ x[:3], 1.0]), np.linalg.solve(c2w, x))


def test_joint_regressor_carries_joints_with_rigid_motion_exactly():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(200, 3))
    joints = rng.normal(scale=0.5, size=(5, 3))
    reg = tm.JointRegressor(x, joints, k=12)
    assert np.allclose(reg(x), joints)
    assert np.allclose(reg.weights.sum(axis=1), 1.0)
    R, t = tm._rotation([1, 2, 3], 70.0), np.array([0.5, -2.0, 1.0])
    moved = np.stack([x, x @ R.T + t])
    assert np.allclose(reg(moved), np.stack([joints, joints @ R.T + t]))


def test_surface_distances_match_brute_force():
    rng = np.random.default_rng(5)
    verts = rng.uniform(-1, 1, (2, 9, 3))
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [0, 4, 8]])
    truth = rng.uniform(-1.5, 1.5, (2, 30, 3))
    got = tm.surface_distances(truth, verts, faces)
    for f in range(2):
        tri = verts[f][faces]
        for i, p in enumerate(truth[f]):
            P = np.repeat(p[None], len(faces), 0)
            q = closest_points_on_triangles(P, tri[:, 0], tri[:, 1], tri[:, 2])
            assert got[f, i] == pytest.approx(np.linalg.norm(q - P, axis=1).min(), abs=1e-12)
