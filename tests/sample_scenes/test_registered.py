"""Registered sequences (sample_scenes.registered): rigid check, files vs memory, ground truth, CLI."""
import json
import os

import numpy as np
import pytest
import trimesh

from articula.addon.cli.main import main as cli_main
from articula.sample_scenes import registered
from articula.sample_scenes.subjects import make_subject
from articula.solver.formats.bundle import load_bundle
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.kinematics import forward_kinematics
from articula.solver.rig.model import Poses


@pytest.fixture(scope="module")
def subject():
    return make_subject("game_engine", "male,thin")


@pytest.mark.parametrize("skin", registered.SKINS)
def test_zero_rotations_reproduce_the_rest_mesh(subject, skin):
    poses = Poses.identity(2, subject.skeleton.num_bones)
    Rm, tm = forward_kinematics(subject.skeleton, poses)
    posed, _ = registered._skin(subject, skin, poses, Rm, tm)
    assert np.abs(posed - subject.vertices).max() < 1e-12


def test_lbs_sequence_matches_an_independent_blend(subject):
    """posed = sum_b w_b (R_b v + t_b) with the stored bone matrices, computed vertex by vertex."""
    verts, faces, gt = registered.posed_sequence("game_engine", "male,thin", 3, skin="lbs", seed=2)
    assert np.array_equal(faces, subject.triangles)
    rng = np.random.default_rng(0)
    M = gt["bone_matrices"]
    for v in rng.choice(len(subject.vertices), 50, replace=False):
        x = np.append(gt["rest_vertices"][v], 1.0)
        w = gt["lbs_weights"][v].astype(np.float64)
        expect = np.einsum("b,nbij,j->ni", w / w.sum(), M, x)[:, :3]
        assert np.abs(verts[:, v] - expect).max() < 1e-5          # float32 weights in the file
    heads = np.einsum("nbij,bj->nbi", M[..., :3, :3], gt["heads"]) + M[..., :3, 3]
    assert np.allclose(heads, gt["posed_heads"])
    # the posed head of a child is its parent's map of the child head (joints stay connected)
    b = 5
    p = gt["parents"][b]
    assert np.allclose(np.einsum("nij,j->ni", M[:, p, :3, :3], gt["heads"][b]) + M[:, p, :3, 3], heads[:, b])


def test_sequence_determinism():
    a = registered.posed_sequence("cmu_mb", None, 4, skin="hybrid", seed=7)[0]
    b = registered.posed_sequence("cmu_mb", None, 4, skin="hybrid", seed=7)[0]
    c = registered.posed_sequence("cmu_mb", None, 4, skin="hybrid", seed=8)[0]
    assert np.array_equal(a, b) and np.abs(a - c).max() > 0.05


def _triangle_set(tris):
    """Oriented triangles as a set, each rotated to start at its smallest index."""
    t = np.asarray(tris)
    k = np.argmin(t, axis=1)
    rolled = np.stack([t[np.arange(len(t)), (k + i) % 3] for i in range(3)], axis=1)
    return set(map(tuple, rolled.tolist()))


@pytest.mark.parametrize("fmt, faces", [("obj", "quads"), ("ply", "triangles")])
def test_files_reread_equal_memory(tmp_path, fmt, faces):
    gt = registered.generate_registered(tmp_path, "mixamo", "female", 5, skin="dqs", fmt=fmt, seed=1, faces=faces)
    names = sorted(os.listdir(tmp_path))
    assert names == ["ground_truth.npz"] + [f"pose_{i:04d}.{fmt}" for i in range(5)]
    tol = 1e-6 if fmt == "obj" else 1e-6 * 3                 # 6 decimals / float32
    # the files in their format's axes (docs/SAMPLES.md): OBJ Y up, a world point (x, y, z) as (x, z, -y)
    assert tuple(gt["file_axes"]) == (("NEGATIVE_Z", "Y") if fmt == "obj" else ("Y", "Z"))
    for i in range(5):
        mesh = trimesh.load(tmp_path / f"pose_{i:04d}.{fmt}", process=False)
        world = gt["posed_vertices"][i]
        in_file = np.c_[world[:, 0], world[:, 2], -world[:, 1]] if fmt == "obj" else world
        assert np.abs(mesh.vertices - in_file).max() < tol
        assert _triangle_set(mesh.faces) == _triangle_set(gt["faces"])   # same oriented triangles
    if faces == "quads":
        lines = (tmp_path / "pose_0004.obj").read_text().splitlines()
        quads = np.array([ln.split()[1:] for ln in lines if ln.startswith("f ")], dtype=int) - 1
        assert np.array_equal(quads, gt["quads"])
    with np.load(tmp_path / "ground_truth.npz") as z:
        for key in ("rest_vertices", "faces", "quads", "parents", "heads", "frames", "pose_rotations",
                    "bone_matrices", "lbs_weights", "posed_vertices"):
            assert np.array_equal(z[key], gt[key]), key
        assert str(z["skin"]) == "dqs" and int(z["seed"]) == 1 and str(z["file_faces"]) == faces
        assert json.loads(str(z["macros"]))["gender"] == 0.0
        assert z["bone_names"].tolist()[:2] == ["Hips", "UpLeg.L"]
        assert z["source_bone_names"].tolist()[1] == "mixamorig:LeftUpLeg"


def test_hybrid_writes_a_model_bundle(tmp_path):
    gt = registered.generate_registered(tmp_path, "cmu_mb", None, 3, skin="hybrid", fmt="ply", seed=0)
    bundle = load_bundle(tmp_path / "ground_truth_model.npz")
    bundle.model.validate()
    assert np.array_equal(bundle.model.anchor, gt["anchor"])
    assert np.array_equal(bundle.model.twist_weights, gt["twist_weights"])
    assert np.array_equal(bundle.poses.rotations, gt["pose_rotations"])
    assert bundle.provenance["rig"] == "cmu_mb" and bundle.provenance["skin"] == "hybrid"
    assert (np.abs(gt["twist_weights"] - gt["swing_weights"]) > 0.1).any()


def test_bad_parameters(tmp_path):
    with pytest.raises(ArticulaInputError, match="skin"):
        registered.posed_sequence(skin="quaternion")
    with pytest.raises(ArticulaInputError, match="motion"):
        registered.posed_sequence(motion="dance")
    with pytest.raises(ArticulaInputError, match="format"):
        registered.generate_registered(tmp_path, fmt="stl")
    assert not os.listdir(tmp_path)


def test_cli_registered(tmp_path, capsys):
    out = tmp_path / "seq"
    code = cli_main(["samples", "registered", "--rig", "cmu_mb", "--poses", "3", "--skin", "hybrid",
                     "--shape", "female,heavy", "--seed", "0", "--out", str(out)])
    assert code == 0 and "3 OBJ meshes" in capsys.readouterr().out
    assert sorted(os.listdir(out))[:2] == ["ground_truth.npz", "ground_truth_model.npz"]
    code = cli_main(["samples", "registered", "--shape", "female,huge", "--out", str(tmp_path / "x")])
    assert code == 2 and "unknown preset 'huge'" in capsys.readouterr().err
