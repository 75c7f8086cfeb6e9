"""Shared inputs of the depth-tracking tests: the built-in template (a real 13,380-vertex MakeHuman body
with a 25-part rig), random poses, and an observation rendered from a posed body by the sample-data depth
renderer (no sensor noise unless asked)."""
import numpy as np
import pytest

from articula.solver.depth import camera as cam
from articula.solver.depth import frames as dp
from articula.solver.rig.pose_sampling import random_poses
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.track_depth.observation import ViewCamera, observe
from articula.solver.track_depth.template import load_template


@pytest.fixture(scope="session")
def template():
    return load_template()


@pytest.fixture(scope="session")
def model(template):
    return template.base


def mild_poses(model, n=1, seed=0, angle=0.4):
    """Random poses with joint angles up to ``angle`` rad and the root left upright."""
    p = random_poses(n, model.skeleton.num_bones, seed=seed, max_twist_deg=np.degrees(angle))
    from articula.solver.geometry.rotations import quat_to_rotvec, rotvec_to_quat
    r = quat_to_rotvec(p.rotations)
    norm = np.linalg.norm(r, axis=-1, keepdims=True)
    r = np.where(norm > angle, r * angle / np.maximum(norm, 1e-12), r)
    r[:, 0] = 0.0
    p.rotations = rotvec_to_quat(r)
    p.translations[:] = 0.0
    p.scales[:] = 1.0
    return p


def front_camera(model, resolution=(320, 240), distance=2.6):
    """A Kinect v1 camera in front of the body (-Y), level with its middle; tracking frame = world."""
    v = model.rest_vertices
    centre = 0.5 * (v.min(0) + v.max(0))
    eye = centre + np.array([0.0, -distance, 0.0])
    return ViewCamera(cam.preset("kinect_v1", resolution), cam.look_at(eye, centre))


def render(model, pose, camera, noise=False, seed=0):
    """The depth image (H, W) metres (NaN = nothing) of the posed model seen by ``camera``."""
    from articula.sample_scenes.depth_render import render_depth
    verts = hybrid_skin(model, pose)[0]
    depth, _ = render_depth(camera.to_camera(verts), model.faces, camera.intr)
    depth = np.where(depth > 0, depth, np.nan).astype(np.float32)
    if noise:
        rng = np.random.default_rng(seed)
        depth = depth + rng.normal(0, 0.003, depth.shape).astype(np.float32)
    return depth


def observation(model, pose, camera, **kw):
    opts = dp.DepthOptions(remove_floor=False)
    return observe(render(model, pose, camera, **kw), dp.pixel_rays(camera.intr), camera, opts)
