"""Meshes with separate islands (an eye, teeth): the rig is learned from the largest island and the
others are carried rigidly by the nearest part (solver.learn.islands)."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.learn.islands import rigid_rest_positions, split_islands
from articula.solver.learn.pipeline import learn_rig
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Model
from articula.solver.rig.skinning import hybrid_skin

from articula.sample_scenes.tube_scans import hybrid_truth

BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def with_eye(M=8, centre=(0.03, -0.10, 1.58), size=0.02):
    """The tube body's hybrid-skinned scans plus a detached box (an "eye") in front of the head, moving
    rigidly with the true head bone (bone 1): ``(truth model with the eye, scans (M, V+8, 3))``."""
    model, poses, _ = hybrid_truth(M)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) - 0.5
    eye = np.asarray(centre) + size * corners
    V, B = model.num_vertices, model.skeleton.num_bones
    full = Model(np.concatenate([model.rest_vertices, eye]), np.concatenate([model.faces, BOX_FACES + V]),
                 model.skeleton, np.concatenate([model.anchor, np.full(8, 1)]),
                 np.concatenate([model.twist_weights, np.zeros((8, B))]),
                 np.concatenate([model.swing_weights, np.zeros((8, B))]))
    return full, hybrid_skin(full, poses)


@pytest.fixture(scope="module")
def eye_run():
    truth, scans = with_eye()
    return truth, scans, learn_rig(scans, truth.faces, parts=8, max_iterations=1, seed=0)


def test_learning_succeeds_and_keeps_every_vertex(eye_run):
    truth, scans, res = eye_run
    V = truth.num_vertices
    assert res.model.num_vertices == V and np.array_equal(res.model.faces, truth.faces)
    assert res.scan_distances.shape == (len(scans), V)
    res.model.validate()
    eye = np.arange(V - 8, V)
    assert np.all(res.model.twist_weights[eye] == 0) and np.all(res.model.swing_weights[eye] == 0)


def test_the_eye_moves_rigidly_with_the_head_part(eye_run):
    truth, scans, res = eye_run
    V = truth.num_vertices
    eye = np.arange(V - 8, V)
    bone = int(res.model.anchor[eye[0]])
    assert np.all(res.model.anchor[eye] == bone)
    # the learned bone that moves like the true head (the head's vertices may be anchored to the root and
    # weighted fully on that bone): the best rigid fit of the head's scanned positions
    head = np.flatnonzero(truth.anchor[:V - 8] == 1)
    Rm, tm = forward_kinematics(res.model.skeleton, res.poses)
    head_rms = []
    for b in range(res.model.skeleton.num_bones):
        x = rigid_rest_positions(Rm[:, b], tm[:, b], scans[:, head])
        posed = np.einsum("mij,vj->mvi", Rm[:, b], x) + tm[:, b, None]
        head_rms.append(np.sqrt(np.mean(np.sum((posed - scans[:, head]) ** 2, axis=2))))
    assert int(np.argmin(head_rms)) == bone
    err = np.linalg.norm(hybrid_skin(res.model, res.poses) - scans, axis=2)
    eye_rms = np.sqrt(np.mean(err[:, eye] ** 2))
    assert eye_rms < max(1.5 * min(head_rms), 1e-3), (eye_rms, min(head_rms))
    info = res.report["islands"]
    assert info["count"] == 1 and info["vertices"] == 8
    row = info["islands"][0]
    assert row["vertices"] == 8 and row["bone"] == res.model.skeleton.names[bone]
    assert row["rms_mm"] == pytest.approx(eye_rms * 1e3, rel=1e-6)
    assert res.report["surface_error_mm"]["count"] == len(scans) * V


def test_rigid_rest_positions_invert_the_motion():
    rng = np.random.default_rng(1)
    R = np.linalg.qr(rng.normal(size=(5, 3, 3)))[0]
    R *= np.sign(np.linalg.det(R))[:, None, None]
    t = rng.normal(size=(5, 3))
    x = rng.normal(size=(7, 3))
    points = np.einsum("mij,vj->mvi", R, x) + t[:, None]
    np.testing.assert_allclose(rigid_rest_positions(R, t, points), x, atol=1e-12)


def test_a_second_body_is_refused_not_carried():
    """An island with at least half the largest island's vertices is a second body: refused by name."""
    model, poses, scans = hybrid_truth(5)
    V = model.num_vertices
    two = np.concatenate([scans, scans + [2.0, 0, 0]], axis=1)
    with pytest.raises(ArticulaInputError, match=r"2 disconnected islands of \[509, 509\].*too large to be carried"):
        learn_rig(two, np.concatenate([model.faces, model.faces + V]), parts=8)
    eye = split_islands(with_eye()[0].faces, V + 8)
    assert len(eye.main) == V and [len(o) for o in eye.others] == [8] and eye.carried == 8
