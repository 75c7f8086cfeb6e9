"""The template's body adaptation: exact linear terms of part lengths and macro shape, recovery of known
scales and shapes from point pairs (the dissertation's ch. 5 §4.6 test: arms x1.1, legs x0.95; its 2% is
missed by the regulariser's pull towards the unscaled neighbours: within 4%, docs/track_depth.md), and
poses re-expressed across rest-frame changes."""
import numpy as np
import pytest

from articula.solver.rig.kinematics import world_rotations
from articula.solver.tracking.blend_body import BlendBody
from articula.solver.track_depth.body_shape import ShapeTerms, same_world_pose, solve_coefficients
from articula.solver.track_depth.body_size import FramePairs, linear_terms, scaled_model, solve_scales

from .conftest import mild_poses


def test_scale_terms_are_exact(model):
    rng = np.random.default_rng(0)
    s = rng.uniform(0.8, 1.2, model.skeleton.num_bones)
    p = mild_poses(model, seed=1)
    p.translations[:] = [0.1, -0.2, 0.05]
    body = BlendBody(model, count=300)
    c, E = linear_terms(model, body.ids, p)
    expect = BlendBody(scaled_model(model, s), ids=body.ids).pose(p).points
    assert np.abs(c + np.einsum("b,mbc->mc", s, E) - expect).max() < 1e-9


def test_scaled_model_keeps_girth_and_frames(model):
    s = np.full(model.skeleton.num_bones, 1.2)
    m = scaled_model(model, s)
    assert np.allclose(m.skeleton.frames, model.skeleton.frames)
    d0 = model.skeleton.tails - model.skeleton.heads
    assert np.allclose(m.skeleton.tails - m.skeleton.heads, 1.2 * d0)


def _pairs(true_model, body_ids, poses):
    return [FramePairs(body_ids, BlendBody(true_model, ids=body_ids).pose(p.take(0)).points, p.take(0))
            for p in poses]


def test_known_part_scales_are_recovered(model):
    names = model.skeleton.names
    s = np.ones(len(names))
    for i, n in enumerate(names):
        if n.startswith(("Arm", "ForeArm")):
            s[i] = 1.1
        if n.startswith(("UpLeg", "Leg.")):
            s[i] = 0.95
    truth = scaled_model(model, s)
    ids = BlendBody(model, count=800).ids
    frames = _pairs(truth, ids, [mild_poses(model, seed=k, angle=0.5) for k in range(3)])
    got = solve_scales(model, frames, np.ones(len(names)))
    big = [i for i, n in enumerate(names) if n.startswith(("Arm", "ForeArm", "UpLeg", "Leg."))]
    assert np.abs(got[big] / s[big] - 1).max() < 0.04
    assert np.abs(got[big] - 1).min() > 0.03          # every one moved most of the way


def test_shape_terms_are_exact_and_coefficients_recovered(template):
    base = template.base
    rng = np.random.default_rng(1)
    coeffs = np.zeros(template.num_basis)
    coeffs[[0, 6, 9]] = rng.uniform(0.2, 0.8, 3)        # one basis vector of three macros
    p = mild_poses(base, seed=2)
    body = BlendBody(base, count=500)
    c0, E = ShapeTerms(template)(body.ids, p)
    shaped = template.shaped(coeffs)
    expect = BlendBody(shaped, ids=body.ids).pose(same_world_pose(base.skeleton, shaped.skeleton, p)).points
    assert np.abs(c0 + np.einsum("k,mkr->mr", coeffs, E) - expect).max() < 1e-9
    frames = [FramePairs(body.ids, expect, p)]
    got = solve_coefficients(ShapeTerms(template), frames)
    # the macro basis is nearly collinear (height, proportions, gender): the body, not the numbers, is unique
    fitted = template.shaped(got)
    pts = BlendBody(fitted, ids=body.ids).pose(same_world_pose(base.skeleton, fitted.skeleton, p)).points
    moved = np.linalg.norm(expect - BlendBody(base, ids=body.ids).pose(p).points, axis=1)
    assert np.median(np.linalg.norm(pts - expect, axis=1)) < 0.1 * np.median(moved)


def test_same_world_pose_keeps_world_rotations(template):
    base, shaped = template.base, template.shaped(np.full(template.num_basis, 0.3))
    p = mild_poses(base, seed=3)
    q = same_world_pose(base.skeleton, shaped.skeleton, p)
    assert np.allclose(world_rotations(base.skeleton, p.rotations), world_rotations(shaped.skeleton, q.rotations))
