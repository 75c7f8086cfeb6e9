"""The template's surface adaptation (an inflated body is recovered, the dissertation's ch. 5 §4.5 test)
and the joint limits' rows (finite differences, box rows only outside the box)."""
import numpy as np

from articula.solver.rig.model import Model
from articula.solver.geometry.normals import vertex_normals
from articula.solver.tracking.blend_body import BlendBody
from articula.solver.tracking.priors import BOX_WEIGHT, CENTRE_WEIGHT, JointBox, generic_limits
from articula.solver.track_depth.surface import SurfaceFit

from .conftest import mild_poses


def test_inflated_body_is_recovered(model):
    n = vertex_normals(model.rest_vertices, model.faces)
    fat = Model(model.rest_vertices + 0.01 * n, model.faces, model.skeleton, model.anchor,
                model.twist_weights, model.swing_weights)
    body = BlendBody(model, count=1500)
    truth = BlendBody(fat, ids=body.ids)
    fit = SurfaceFit(model)
    for k in range(3):
        p = mild_poses(model, seed=k, angle=0.3)
        fit.add_frame(body.ids, truth.pose(p).points, p, np.array([0.0, -3.0, 1.0]))
    d = fit.displacements()
    assert abs(np.median(d[body.ids]) - 0.01) < 0.002
    assert abs(np.median(d) - 0.01) < 0.003            # carried to the vertices between the tracked ones
    far = fit.sum_w[body.ids]
    assert (far > 0).all()


def test_generic_limit_rows_match_finite_differences_and_vanish_inside(model):
    """The template's generic limits (box and centre pull) on the blend body: the gradient is the
    energy's central difference; inside a wide box only the weak centre pull is left."""
    body = BlendBody(model, count=200)
    lim = generic_limits(model.skeleton)
    assert len(lim.bones) > 10
    p = mild_poses(model, seed=5, angle=0.8)
    posed = body.pose(p)
    lin = lim.linearise(body, posed)
    rng = np.random.default_rng(0)
    d = rng.normal(size=body.size) * 1e-6
    d[:3] = 0
    up, down = body.pose(body.moved(p, d)), body.pose(body.moved(p, -d))
    fd = lim.energy(body, up) - lim.energy(body, down)
    assert abs(fd - 2 * lin.g @ d) < 1e-3 * abs(fd) + 1e-12
    B = model.skeleton.num_bones
    inside = JointBox(np.full((B, 3), -10.0), np.full((B, 3), 10.0), BOX_WEIGHT, CENTRE_WEIGHT)
    assert np.abs(inside.linearise(body, posed).g).max() < 0.01 * np.abs(lin.g).max()
