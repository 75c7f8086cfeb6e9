"""Model validation and the "articula-model/1" bundle: round trip and every bad-input case."""
import json
import os

import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.formats.bundle import FORMAT, load_bundle, save_bundle
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.model import Poses


@pytest.fixture
def model():
    m = synthetic.random_model(300, seed=2)
    m.faces = np.array([[0, 1, 2], [2, 3, 4]], dtype=np.int32)
    return m


def raw_arrays(path):
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}


def rewrite(path, **changes):
    arrays = raw_arrays(path)
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez(path, **arrays)


def test_roundtrip_exact(tmp_path, model):
    poses = synthetic.random_poses(3, model.skeleton.num_bones, seed=1)
    path = tmp_path / "m.npz"
    save_bundle(path, model, poses, {"source": "unit test", "frames": [1, 2]})
    arrays = raw_arrays(path)
    assert set(arrays) == {"format", "rest_vertices", "faces", "bone_names", "parents", "heads", "tails", "frames",
                           "anchor", "twist_weights", "swing_weights", "pose_rotations", "pose_translations",
                           "pose_scales", "provenance"}
    assert str(arrays["format"]) == FORMAT
    assert arrays["faces"].dtype == np.int32 and arrays["parents"].dtype == np.int32
    assert arrays["twist_weights"].dtype == np.float32 and arrays["heads"].dtype == np.float64
    b = load_bundle(path)
    m = b.model
    np.testing.assert_array_equal(m.rest_vertices, model.rest_vertices)
    np.testing.assert_array_equal(m.faces, model.faces)
    np.testing.assert_array_equal(m.twist_weights, model.twist_weights)
    np.testing.assert_array_equal(m.swing_weights, model.swing_weights)
    np.testing.assert_array_equal(m.anchor, model.anchor)
    np.testing.assert_array_equal(m.skeleton.frames, model.skeleton.frames)
    assert m.skeleton.names == model.skeleton.names
    np.testing.assert_array_equal(b.poses.rotations, poses.rotations)
    np.testing.assert_array_equal(b.poses.scales, poses.scales)
    assert b.provenance == {"source": "unit test", "frames": [1, 2]}


def test_roundtrip_without_poses(tmp_path, model):
    save_bundle(tmp_path / "m.npz", model)
    b = load_bundle(tmp_path / "m.npz")
    assert b.poses is None and b.provenance == {}


def test_extra_arrays_round_trip_and_may_not_take_a_bundle_key(tmp_path, model):
    """Further numeric arrays (a tracked bundle's pass-1 record) come back exactly; one named like a
    bundle key, or not numeric, is refused before anything is written."""
    extra = {"pass1_last": np.random.default_rng(0).normal(size=(3, 9)), "pass1_fitted": np.array([1, 0, 1], bool)}
    save_bundle(tmp_path / "m.npz", model, extra=extra)
    got = load_bundle(tmp_path / "m.npz").extra
    assert set(got) == set(extra) and all(np.array_equal(got[k], extra[k]) for k in extra)
    assert got["pass1_fitted"].dtype == bool
    for bad in ({"faces": np.zeros(3)}, {"pose_scales": np.ones(2)}, {"names": np.array(["a"])}):
        with pytest.raises(ArticulaInputError, match="extra array"):
            save_bundle(tmp_path / "n.npz", model, extra=bad)
    assert not os.path.exists(tmp_path / "n.npz")


def test_missing_file_names_path(tmp_path):
    with pytest.raises(ArticulaInputError, match="nope.npz"):
        load_bundle(tmp_path / "nope.npz")


def test_garbage_file(tmp_path):
    p = tmp_path / "bad.npz"
    p.write_bytes(b"not a zip")
    with pytest.raises(ArticulaInputError, match="bad.npz"):
        load_bundle(p)


def bad_case(model):
    """(description, changes to the saved arrays, expected message pattern)."""
    sk = model.skeleton
    B = sk.num_bones
    cases = []
    w = model.twist_weights.copy()
    v = int(np.flatnonzero(model.anchor == 0)[0])
    w[v, 7] = 0.1                               # bone 7 (upper_arm.L) is not a child of the pelvis
    cases.append(("weights on non-child", dict(twist_weights=w), r"twist_weights: vertex %d .*not a child" % v))
    w = model.swing_weights.copy()
    w[5, :] = 0
    kids = sk.children(int(model.anchor[5]))
    w[5, kids[0]] = 1.5
    cases.append(("weight > 1", dict(swing_weights=w), r"swing_weights: vertex 5.*outside \[0, 1\]"))
    rot = np.zeros((2, B, 4))
    rot[..., 0] = 1
    rot[1, 4] = [1, 0.1, 0, 0]
    cases.append(("non-unit quaternion", dict(pose_rotations=rot, pose_translations=np.zeros((2, 3)),
                                               pose_scales=np.ones(2)), r"pose_rotations: frame 1, bone 4"))
    tails = sk.tails.copy()
    tails[3] = sk.heads[3]
    cases.append(("head == tail", dict(tails=tails), r"tails: bone 3 .*head == tail"))
    parents = sk.parents.copy()
    parents[2] = 5
    cases.append(("cycle / order", dict(parents=parents), r"parents: bone 2"))
    heads = sk.heads.copy()
    heads[6, 1] = np.nan
    cases.append(("NaN", dict(heads=heads), r"heads: non-finite value at index \(6, 1\)"))
    frames = sk.frames.copy()
    frames[1] = frames[1] @ np.diag([1.0, 1.0, -1.0])
    cases.append(("left-handed frame", dict(frames=frames), r"frames: frame of bone 1 has det -1"))
    cases.append(("wrong format", dict(format=np.array("articula-model/9")),
                  r"key 'format' is 'articula-model/9', expected 'articula-model/1'$"))
    cases.append(("missing key", dict(anchor=None), r"missing key 'anchor'"))
    cases.append(("bad anchor", dict(anchor=np.full(model.num_vertices, B, dtype=np.int32)), r"anchor: vertex 0"))
    cases.append(("float faces", dict(faces=model.faces.astype(float)), r"'faces' must be integer"))
    cases.append(("face out of range", dict(faces=np.array([[0, 1, 10 ** 6]], dtype=np.int32)), r"faces: face 0"))
    cases.append(("bad weight shape", dict(twist_weights=model.twist_weights[:, :3]), r"twist_weights: expected shape"))
    cases.append(("bad provenance", dict(provenance=np.array("{not json")), r"provenance"))
    cases.append(("bad scale", dict(pose_rotations=np.tile([1.0, 0, 0, 0], (1, B, 1)), pose_scales=np.zeros(1),
                                    pose_translations=np.zeros((1, 3))), r"pose_scales: frame 0"))
    return cases


def test_each_bad_bundle_is_rejected_with_key(tmp_path, model):
    for i, (desc, changes, pattern) in enumerate(bad_case(model)):
        path = tmp_path / f"bad{i}.npz"
        save_bundle(path, model)
        rewrite(path, **changes)
        with pytest.raises(ArticulaInputError, match=pattern) as err:
            load_bundle(path)
        assert str(path) in str(err.value), desc


def test_pickled_object_arrays_are_refused(tmp_path, model):
    path = tmp_path / "obj.npz"
    save_bundle(path, model)
    arrays = raw_arrays(path)
    arrays["bone_names"] = np.array(model.skeleton.names, dtype=object)
    np.savez(path, **arrays)
    with pytest.raises(ArticulaInputError, match=r"obj.npz: key 'bone_names' holds Python objects") as err:
        load_bundle(path)
    assert "allow_pickle" not in str(err.value)


def test_empty_path_says_no_bundle_file_given():
    with pytest.raises(ArticulaInputError, match=r"^no bundle file given$"):
        load_bundle("")


def test_random_bytes_are_not_a_model_bundle(tmp_path):
    path = tmp_path / "noise.npz"
    path.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(ArticulaInputError) as err:
        load_bundle(path)
    assert str(err.value) == f"{path}: not a model bundle (not a valid .npz archive of arrays)"


def test_zip_of_other_files_is_not_a_model_bundle(tmp_path):
    import zipfile
    path = tmp_path / "notes.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("readme.txt", "hello")
    with pytest.raises(ArticulaInputError, match=r"notes.npz: not a model bundle \(not a valid .npz archive"):
        load_bundle(path)


def test_weights_summing_above_one_on_child_bones_only_are_refused_on_load(tmp_path, model):
    """Each weight in [0, 1] and on a child of the anchor: only the weight-sum rule refuses the file."""
    sk = model.skeleton
    v = next(v for v in range(model.num_vertices) if len(sk.children(int(model.anchor[v]))) >= 2)
    c1, c2 = sk.children(int(model.anchor[v]))[:2]
    path = tmp_path / "sum.npz"
    save_bundle(path, model)
    w = model.twist_weights.copy()
    w[v] = 0
    w[v, c1], w[v, c2] = 0.7, 0.7
    rewrite(path, twist_weights=w)
    with pytest.raises(ArticulaInputError, match=rf"sum.npz: twist_weights: vertex {v}: weights sum to 1\.4 > 1"):
        load_bundle(path)


def test_near_unit_quaternions_are_normalised_on_load_with_a_note(tmp_path, model):
    poses = synthetic.random_poses(3, model.skeleton.num_bones, seed=1)
    path = tmp_path / "f32.npz"
    save_bundle(path, model, poses)
    rot = poses.rotations.astype(np.float32)        # a float32 round trip: norms off by ~1e-7
    rot[1, 2] *= np.float32(1.00005)
    rewrite(path, pose_rotations=rot)
    b = load_bundle(path)
    norms = np.linalg.norm(b.poses.rotations, axis=2)
    assert abs(norms[1, 2] - 1.0) < 1e-12 and np.abs(norms - 1.0).max() <= 1e-6
    np.testing.assert_allclose(b.poses.rotations, poses.rotations, atol=1e-6)
    assert len(b.notes) == 1 and str(path) in b.notes[0] and "frame 1, bone 2" in b.notes[0]
    rot[1, 2] *= np.float32(1.001)
    rewrite(path, pose_rotations=rot)
    with pytest.raises(ArticulaInputError, match=r"f32.npz: pose_rotations: frame 1, bone 2: quaternion norm 1\.00"):
        load_bundle(path)
    save_bundle(path, model, poses)
    assert load_bundle(path).notes == []


def test_save_refuses_invalid_model_and_leaves_no_file(tmp_path, model):
    model.swing_weights[0, :] = 0.9            # sum > 1 (and possibly non-children)
    with pytest.raises(ArticulaInputError, match="swing_weights: vertex 0"):
        save_bundle(tmp_path / "x.npz", model)
    assert not os.listdir(tmp_path)


def test_provenance_must_be_json(tmp_path, model):
    with pytest.raises(ArticulaInputError, match="provenance"):
        save_bundle(tmp_path / "x.npz", model, provenance={"a": object()})
    save_bundle(tmp_path / "y.npz", model, provenance={"a": 1})
    assert json.loads(str(raw_arrays(tmp_path / "y.npz")["provenance"])) == {"a": 1}


def test_model_validate_messages():
    m = synthetic.random_model(50, seed=4)
    m.validate()
    m.skeleton.names[3] = m.skeleton.names[2]
    with pytest.raises(ArticulaInputError, match="duplicate name 'chest'"):
        m.validate()


def test_poses_identity_and_len():
    p = Poses.identity(5, 3)
    assert len(p) == 5 and p.rotations.shape == (5, 3, 4)
    p.validate(3)
    with pytest.raises(ArticulaInputError, match=r"pose_rotations: expected shape \(N, 4, 4\)"):
        p.validate(4)
