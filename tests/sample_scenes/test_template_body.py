"""The shipped template body (solver.track_depth.template) against the MakeHuman subjects it comes from:
the file equals a fresh build of ``tools/make_template_body.py``, and the linear macro basis reproduces
``make_subject`` bodies.  Asserted bounds: one macro moved, vertices and joints within 1 mm; weight 0.8
with gender 0.2 together (the macro targets interact, the basis adds them), vertices within 6 mm (mean
within 1 mm) and joints within 1 mm."""
import importlib.util
import json
import os

import numpy as np
import pytest

from articula.sample_scenes.subjects import make_subject
from articula.solver.track_depth.template import TEMPLATE_PATH, load_template

from ..conftest import REPO


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("make_template_body",
                                                  os.path.join(REPO, "tools", "make_template_body.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def template():
    return load_template()


def test_shipped_file_equals_a_fresh_build(tool):
    built = tool.build_arrays()
    with np.load(TEMPLATE_PATH, allow_pickle=False) as z:
        shipped = {k: z[k] for k in z.files}
    assert sorted(shipped) == sorted(built)
    for key, value in built.items():
        assert shipped[key].dtype == value.dtype and shipped[key].shape == value.shape, key
        if key == "frames":         # built from sines and products: numpy 1.26 and 2 differ in the last bit
            np.testing.assert_allclose(shipped[key], value, rtol=0, atol=1e-12)
        elif key == "provenance":
            assert json.loads(str(shipped[key])) == json.loads(str(value))
        else:
            np.testing.assert_array_equal(shipped[key], value, err_msg=key)


def test_base_is_the_default_subject_with_the_fingers_merged(tool, template):
    subject = make_subject("cmu_mb")
    merged = tool.merge_bones(subject)
    np.testing.assert_array_equal(template.base.rest_vertices, subject.vertices)
    np.testing.assert_array_equal(template.base.faces, subject.triangles)
    assert template.base.skeleton.names == merged.skeleton.names
    # finger weight joined the hand: rows still sum to 1, the hand column holds the hand and its fingers
    names = subject.skeleton.names
    np.testing.assert_allclose(merged.lbs_weights.sum(axis=1), 1.0, atol=1e-12)
    for side in "LR":
        parts = [names.index(f"{n}.{side}") for n in ("Hand", "Thumb", "FingerBase", "HandFinger1")]
        np.testing.assert_allclose(merged.lbs_weights[:, merged.skeleton.names.index(f"Hand.{side}")],
                                   subject.lbs_weights[:, parts].sum(axis=1), atol=1e-12)
    # swing/twist weights as Subject.hybrid_model derives them (twist ramp on)
    model = merged.hybrid_model()
    np.testing.assert_array_equal(template.base.anchor, model.anchor)
    np.testing.assert_array_equal(template.base.twist_weights, model.twist_weights)
    assert (template.base.twist_weights != template.base.swing_weights).any()


@pytest.mark.parametrize("macros, vertex_max, vertex_mean, joint_max", [
    ({"weight": 0.8}, 1e-3, 1e-3, 1e-3),
    ({"gender": 0.2}, 1e-3, 1e-3, 1e-3),
    ({"age": 0.1}, 1e-3, 1e-3, 1e-3),
    ({"weight": 0.8, "gender": 0.2}, 6e-3, 1e-3, 1e-3),
])
def test_macro_basis_reproduces_the_subjects(tool, template, macros, vertex_max, vertex_mean, joint_max):
    subject = tool.merge_bones(make_subject("cmu_mb", macros))
    model = template.shaped(template.macro_coefficients(macros))
    err = np.linalg.norm(model.rest_vertices - subject.vertices, axis=1)
    assert err.max() < vertex_max and err.mean() < vertex_mean
    for key in ("heads", "tails"):
        err = np.linalg.norm(getattr(model.skeleton, key) - getattr(subject.skeleton, key), axis=1)
        assert err.max() < joint_max, key
    moved = np.linalg.norm(model.rest_vertices - template.base.rest_vertices, axis=1)
    assert moved.max() > 0.01                          # the comparison is not between two default bodies
