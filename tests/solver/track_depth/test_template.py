"""The built-in template body (solver.track_depth.template): the shipped file, the rig, the linear shape
basis, the macro mapping and refused files."""
import json

import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.track_depth.template import FORMAT, TEMPLATE_PATH, load_template

FINGER_WORDS = ("finger", "thumb", "index", "middle", "ring", "pinky")


@pytest.fixture(scope="module")
def template():
    return load_template()


def test_shipped_file_loads(template):
    base = template.base
    base.validate()
    assert base.rest_vertices.shape == (13380, 3) and base.faces.shape == (26756, 3)
    assert template.rig == "cmu_mb" and template.provenance["licence"].startswith("CC0")
    K, B = template.num_basis, base.skeleton.num_bones
    assert template.vertex_deltas.shape == (K, 13380, 3) and template.vertex_deltas.dtype == np.float64
    assert template.head_deltas.shape == template.tail_deltas.shape == (K, B, 3)
    assert {m: template.macro_defaults[m] for m in set(template.basis_macros)} == dict.fromkeys(
        ("gender", "age", "muscle", "weight", "height", "proportions"), 0.5)
    v = base.rest_vertices                                    # metres, Z up, feet on the ground, facing -Y
    assert v[:, 2].min() == pytest.approx(0.0, abs=1e-12) and 1.5 < v[:, 2].max() < 1.8
    assert np.abs(v[:, 0]).max() < 1.0


def test_bones_pair_up_and_mirror(template):
    sk = template.base.skeleton
    index = {n: i for i, n in enumerate(sk.names)}
    lefts = sorted(n[:-2] for n in sk.names if n.endswith(".L"))
    assert lefts == sorted(n[:-2] for n in sk.names if n.endswith(".R")) and len(lefts) >= 8
    flip = np.array([-1.0, 1.0, 1.0])
    for stem in lefts:
        i, j = index[stem + ".L"], index[stem + ".R"]
        assert sk.heads[i, 0] > 0, stem                                      # the character's left is +X
        assert np.abs(sk.heads[i] * flip - sk.heads[j]).max() < 1e-3, stem
        assert np.abs(sk.tails[i] * flip - sk.tails[j]).max() < 1e-3, stem
        assert sk.names[sk.parents[i]].replace(".L", ".R") == sk.names[sk.parents[j]], stem


def test_compact_rig_without_fingers(template):
    sk = template.base.skeleton
    assert sk.num_bones == 25 and sk.names[0] == "Hips"
    assert all(0 <= sk.parents[b] < b for b in range(1, sk.num_bones))
    assert not [n for n in sk.names if any(w in n.lower() for w in FINGER_WORDS)]
    for side in "LR":
        hand = sk.names.index(f"Hand.{side}")
        assert sk.children(hand) == [] and sk.names[sk.parents[hand]] == f"ForeArm.{side}"
        # the finger skin moves with the hand: the palm and fingertips are anchored to it
        x = template.base.rest_vertices[:, 0]
        tip = np.argmax(x) if side == "L" else np.argmin(x)
        assert template.base.anchor[tip] == hand


def test_zero_coefficients_give_the_base(template):
    model, base = template.shaped(np.zeros(template.num_basis)), template.base
    for key in ("rest_vertices", "faces", "anchor", "twist_weights", "swing_weights"):
        np.testing.assert_array_equal(getattr(model, key), getattr(base, key), err_msg=key)
    for key in ("heads", "tails", "frames", "parents"):
        np.testing.assert_array_equal(getattr(model.skeleton, key), getattr(base.skeleton, key), err_msg=key)
    assert model.skeleton.names == base.skeleton.names


def test_shaped_is_linear(template):
    rng = np.random.default_rng(3)
    a, b = rng.uniform(0, 1, (2, template.num_basis))
    base = template.base

    def offsets(c):
        m = template.shaped(c)
        return m.rest_vertices - base.rest_vertices, m.skeleton.heads - base.skeleton.heads

    (va, ha), (vb, hb), (vab, hab) = offsets(a), offsets(b), offsets(0.5 * a + 0.7 * b)
    np.testing.assert_allclose(vab, 0.5 * va + 0.7 * vb, atol=1e-12)
    np.testing.assert_allclose(hab, 0.5 * ha + 0.7 * hb, atol=1e-12)
    assert np.abs(va).max() > 0.01 and np.abs(ha).max() > 0.01         # the basis moves things


def test_shapes_keep_the_feet_on_the_ground(template):
    base_top = template.base.rest_vertices[:, 2].max()
    for macro in set(template.basis_macros):
        for value in (0.0, 0.1875, 1.0):
            v = template.shaped(template.macro_coefficients({macro: value})).rest_vertices
            assert abs(v[:, 2].min()) < 5e-4, (macro, value)
    tall = template.shaped(template.macro_coefficients({"height": 1.0})).rest_vertices
    assert tall[:, 2].max() > base_top + 0.1


def _angle(a, b):
    """(B,) angles between rows of a and b (B, 3), accurate for small angles."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("bi,bi->b", a, b))


@pytest.mark.parametrize("macros", [{"weight": 0.8}, {"gender": 0.0, "height": 0.7}, {"age": 0.1, "muscle": 1.0},
                                    "random"])
def test_frames_stay_orthonormal_along_the_bones(template, macros):
    c = (np.random.default_rng(5).uniform(0, 1, template.num_basis) if macros == "random"
         else template.macro_coefficients(macros))
    model = template.shaped(c)
    model.validate()                                            # orthonormal, det +1, Y = (tail - head)/|.|
    sk, base = model.skeleton, template.base.skeleton
    np.testing.assert_allclose(np.einsum("bji,bjk->bik", sk.frames, sk.frames),
                               np.broadcast_to(np.eye(3), sk.frames.shape), atol=1e-12)
    y = (sk.tails - sk.heads) / np.linalg.norm(sk.tails - sk.heads, axis=1, keepdims=True)
    np.testing.assert_allclose(sk.frames[:, :, 1], y, atol=1e-12)
    # the roll is kept: X and Z turn by no more than Y does (the smallest rotation between the Y axes)
    turn_y = _angle(base.frames[:, :, 1], y)
    for axis in (0, 2):
        assert (_angle(base.frames[:, :, axis], sk.frames[:, :, axis]) <= turn_y + 1e-12).all()
    assert turn_y.max() > 1e-3


def test_macro_coefficients(template):
    names = template.basis_names
    c = template.macro_coefficients({"weight": 0.8})
    assert c[names.index("weight-high")] == pytest.approx(0.6) and np.count_nonzero(c) == 1
    c = template.macro_coefficients({"weight": 0.25, "gender": 1.0})
    assert c[names.index("weight-low")] == pytest.approx(0.5) and c[names.index("gender-high")] == pytest.approx(1.0)
    assert np.count_nonzero(c) == 2
    c = template.macro_coefficients({"age": 0.1})        # past the child category (0.1875): two pieces
    assert c[names.index("age-low")] == pytest.approx(1.0)
    assert c[names.index("age-low2")] == pytest.approx((0.1875 - 0.1) / 0.1875)
    assert not template.macro_coefficients({}).any()
    assert not template.macro_coefficients({m: 0.5 for m in template.basis_macros}).any()   # the defaults


@pytest.mark.parametrize("macros, message", [
    ({"wieght": 0.6}, "unknown macro 'wieght'"), ({"african": 0.5}, "unknown macro 'african'"),
    ({"weight": 1.2}, "'weight' = 1.2 is outside"), ({"age": -0.1}, "outside"), ({"height": float("nan")}, "outside"),
    ({"muscle": "a lot"}, "not a number"),
])
def test_macro_coefficients_refuse_bad_input(template, macros, message):
    with pytest.raises(ArticulaInputError, match=message):
        template.macro_coefficients(macros)


def test_shaped_refuses_wrong_coefficients(template):
    with pytest.raises(ArticulaInputError, match="expected 13 finite values"):
        template.shaped(np.zeros(3))
    with pytest.raises(ArticulaInputError, match="finite"):
        template.shaped(np.full(template.num_basis, np.nan))


def _rewrite(tmp_path, change):
    with np.load(TEMPLATE_PATH, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    path = tmp_path / "template.npz"
    np.savez(path, **arrays)
    return path


def test_refuses_broken_files(tmp_path):
    missing = tmp_path / "nothing.npz"
    with pytest.raises(ArticulaInputError, match="nothing.npz: no such template file"):
        load_template(missing)
    text = tmp_path / "text.npz"
    text.write_text("not an archive")
    with pytest.raises(ArticulaInputError, match="text.npz: not a template body"):
        load_template(text)
    path = _rewrite(tmp_path, lambda a: a.pop("tail_deltas"))
    with pytest.raises(ArticulaInputError, match="template.npz: missing key 'tail_deltas'"):
        load_template(path)
    path = _rewrite(tmp_path, lambda a: a.update(format=np.array("articula-model/1")))
    with pytest.raises(ArticulaInputError, match=f"key 'format' is 'articula-model/1', expected '{FORMAT}'"):
        load_template(path)
    path = _rewrite(tmp_path, lambda a: a.update(vertex_deltas=a["vertex_deltas"][:, :100]))
    with pytest.raises(ArticulaInputError, match=r"key 'vertex_deltas': expected shape \(13, 13380, 3\)"):
        load_template(path)
    path = _rewrite(tmp_path, lambda a: a.update(parents=a["parents"][::-1].copy()))
    with pytest.raises(ArticulaInputError, match="template.npz: parents"):
        load_template(path)
    path = _rewrite(tmp_path, lambda a: a.update(provenance=np.array("{not json")))
    with pytest.raises(ArticulaInputError, match="key 'provenance' is not valid JSON"):
        load_template(path)
    path = _rewrite(tmp_path, lambda a: a.update(basis_names=np.array([object()] * 13, dtype=object)))
    with pytest.raises(ArticulaInputError, match="template.npz"):
        load_template(path)


def test_provenance_names_the_sources(template):
    text = json.dumps(template.provenance)
    assert "MakeHuman" in text and "MPFB2" in text and "tools/make_template_body.py" in text
