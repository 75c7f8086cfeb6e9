"""The ICP fit's floor rows (``icp.add_floor_rows``): the body cannot sink into the floor.  The floor removal
cuts the soles and toes out of the observation (the lowest 3 cm here), so nothing but the floor rows says
where the toes are; from a start with the feet turned 20 degrees toes-down, the fit must bring them back
above the floor, towards the rendered body's true feet."""
import copy

import numpy as np

from articula.solver.geometry.rotations import quat_mul, rotvec_to_quat
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.track_depth import icp
from articula.solver.tracking.blend_body import BlendBody
from articula.solver.track_depth.options import DepthTrackOptions

from .conftest import front_camera, mild_poses, observation

CUT_M = 0.03       # observed points this close to the floor are removed (as the floor removal does)
FEET = ("Foot.L", "ToeBase.L", "Foot.R", "ToeBase.R")


def _cut_at_the_floor(obs, floor_z):
    obs.floor = (np.array([0.0, 0.0, 1.0]), -floor_z)
    keep = obs.height(obs.points) > CUT_M
    obs.points, obs.normals, obs.pixels, obs.boundary = (a[keep] for a in (obs.points, obs.normals, obs.pixels,
                                                                            obs.boundary))
    return obs


def test_floor_rows_lift_toes_out_of_the_floor(model):
    camera = front_camera(model)
    truth = mild_poses(model, seed=0, angle=0.0)
    true_verts = hybrid_skin(model, truth)[0]
    floor_z = true_verts[:, 2].min()                    # the body stands on the floor
    obs = _cut_at_the_floor(observation(model, truth, camera), floor_z)
    start = copy.deepcopy(truth)
    toes_down = rotvec_to_quat(np.array([np.radians(20.0), 0.0, 0.0]))
    for name in FEET:
        b = model.skeleton.names.index(name)
        start.rotations[0, b] = quat_mul(start.rotations[0, b], toes_down)
    assert hybrid_skin(model, start)[0][:, 2].min() - floor_z < -0.05       # the start sinks 5+ cm
    fit = icp.fit_frame(BlendBody(model), obs, camera, start, DepthTrackOptions(tracker="icp"))
    verts = hybrid_skin(model, fit.pose)[0]
    feet = np.flatnonzero(true_verts[:, 2] - floor_z < 0.08)
    assert verts[:, 2].min() - floor_z > -0.01
    assert np.linalg.norm(verts[feet] - true_verts[feet], axis=1).max() < 0.023
