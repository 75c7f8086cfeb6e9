"""The template's surface adaptation (an inflated body is recovered, the dissertation's ch. 5 §4.5 test)
and the joint limits' rows (finite differences, box rows only outside the box)."""
import numpy as np

from articula.solver.geometry.rotations import quat_to_rotvec
from articula.solver.rig.model import Model
from articula.solver.geometry.normals import vertex_normals
from articula.solver.track_depth.body import TrackingBody
from articula.solver.track_depth.limits import JointLimits
from articula.solver.track_depth.normal_equations import System
from articula.solver.track_depth.surface import SurfaceFit

from .conftest import mild_poses


def test_inflated_body_is_recovered(model):
    n = vertex_normals(model.rest_vertices, model.faces)
    fat = Model(model.rest_vertices + 0.01 * n, model.faces, model.skeleton, model.anchor,
                model.twist_weights, model.swing_weights)
    body = TrackingBody(model, count=1500)
    truth = TrackingBody(fat, ids=body.ids)
    fit = SurfaceFit(model)
    for k in range(3):
        p = mild_poses(model, seed=k, angle=0.3)
        fit.add_frame(body.ids, truth.pose(p).points, p, np.array([0.0, -3.0, 1.0]))
    d = fit.displacements()
    assert abs(np.median(d[body.ids]) - 0.01) < 0.002
    assert abs(np.median(d) - 0.01) < 0.003            # carried to the vertices between the tracked ones
    far = fit.sum_w[body.ids]
    assert (far > 0).all()


def test_limit_rows_match_finite_differences_and_vanish_inside(model):
    body = TrackingBody(model, count=200)
    lim = JointLimits(model.skeleton)
    p = mild_poses(model, seed=5, angle=0.8)
    posed = body.pose(p)
    s = System(body.num_bones)
    lim.add_to(s, posed, p)
    # the gradient of the limits' energy by finite differences of the bone-local rotation vectors
    def energy(pose):
        r = quat_to_rotvec(pose.rotations[0, lim.bones])
        over = r - np.clip(r, lim.lower[lim.bones], lim.upper[lim.bones])
        pull = (r - lim.centre[lim.bones]) / lim.width[lim.bones]
        from articula.solver.track_depth.limits import BOX_WEIGHT, CENTRE_WEIGHT
        return BOX_WEIGHT * (over ** 2).sum() + CENTRE_WEIGHT * (pull ** 2).sum()
    rng = np.random.default_rng(0)
    d = rng.normal(size=body.num_params) * 1e-6
    d[:3] = 0
    e0, e1 = energy(p), energy(body.apply(p, d, posed))
    assert abs((e1 - e0) - 2 * s.g @ d) < 1e-3 * abs(e1 - e0) + 1e-12
    inside = JointLimits(model.skeleton, lower=np.full((model.skeleton.num_bones, 3), -10.0),
                         upper=np.full((model.skeleton.num_bones, 3), 10.0))
    s2 = System(body.num_bones)
    inside.add_to(s2, posed, p)
    assert np.abs(s2.g).max() < 0.01 * np.abs(s.g).max()
