"""Parts out of view (solver.track_depth.out_of_view) and the standing checks (solver.track_depth.standing)
on the template body: a camera that sees the hips up flags both legs and holds them straight, the fit then
keeps them below the hips; an upside-down pose and a leg folded up are findings, the rest pose none; a part
laid where the camera sees through is named."""
import numpy as np

from articula.solver.depth import camera as cam
from articula.solver.geometry.rotations import matrix_to_quat, rotvec_to_quat
from articula.solver.rig.model import Poses
from articula.solver.roles import role_bones
from articula.solver.track_depth import icp
from articula.solver.tracking.blend_body import BlendBody
from articula.solver.tracking.priors import generic_limits
from articula.solver.track_depth.observation import ViewCamera
from articula.solver.track_depth.options import DepthTrackOptions
from articula.solver.track_depth.out_of_view import Parts, part_name
from articula.solver.track_depth.standing import Standing

from .conftest import front_camera, mild_poses, observation

UP = np.array([0.0, 0.0, 1.0])


def _upper_camera(model):
    """A camera 1.6 m in front of the chest, looking level: the legs are below the image."""
    v = model.rest_vertices
    chest = np.array([0.5 * (v[:, 0].min() + v[:, 0].max()), 0.0, v[:, 2].min() + 0.72 * np.ptp(v[:, 2])])
    return ViewCamera(cam.preset("kinect_v1", (320, 240)), cam.look_at(chest + [0, -1.3, 0], chest))


def _heights(body, pose):
    roles = role_bones(body.model.skeleton.names)
    h = body.pose(pose).joints @ UP
    return h[roles["hips"]], h[[roles["foot.L"], roles["foot.R"]]]


def test_part_names():
    assert part_name("thigh.L") == "left leg" and part_name("forearm.R") == "right forearm"
    assert part_name("head") == "head" and part_name("upper_arm.R") == "right arm"


def test_legs_below_the_image_are_flagged_and_held_straight(model):
    body = BlendBody(model)
    parts = Parts(body)
    camera = _upper_camera(model)
    pose = Poses.identity(1, model.skeleton.num_bones)
    names, bones, targets = parts.out_of_view(body, pose, camera)
    assert set(names) == {"left leg", "right leg"}
    assert np.allclose(targets, 0.0)                         # held at the rest pose's straight legs
    sk = model.skeleton
    hip_links = [role_bones(sk.names)[r] for r in ("hip.L", "hip.R")]
    assert set(hip_links) <= set(bones.tolist())             # the pelvis links that swing a leg are held too
    whole = front_camera(model)
    assert parts.out_of_view(body, pose, whole)[0] == []      # seen whole: nothing held


def test_held_legs_stay_below_the_hips_in_a_fit(model):
    """The legs start folded up (feet above the hips) on a frame that sees the hips up: with the parts out
    of view held, the ICP fit puts them straight below the hips; the checks find the folded start."""
    body = BlendBody(model)
    parts = Parts(body)
    camera = _upper_camera(model)
    truth = mild_poses(model, seed=3, angle=0.2)
    obs = observation(model, truth, camera)
    folded = truth.take(0)
    roles = role_bones(model.skeleton.names)
    for r in ("thigh.L", "thigh.R"):
        folded.rotations[0, roles[r]] = rotvec_to_quat(np.array([2.6, 0.0, 0.0]))
    hips, feet = _heights(body, folded)
    assert (feet > hips).all()
    standing = Standing(body, parts)
    assert any("above the hips" in f for f in standing.findings(body, folded, obs, camera, UP)[0])
    opts = DepthTrackOptions()
    limits = [generic_limits(model.skeleton)]
    names = parts.out_of_view(body, folded, camera)[0]
    assert set(names) == {"left leg", "right leg"}
    _, start, held = parts.hold(body, folded, camera, limits)
    fit = icp.fit_frame(body, obs, camera, start, opts, held)
    hips, feet = _heights(body, fit.pose)
    assert (feet < hips - 0.5).all()
    assert standing.findings(body, fit.pose, obs, camera, UP) == ([], [])


def _rest_seen(model, noise=False):
    """``(body, standing, camera, rest pose, observation of the rest pose)`` from in front."""
    body = BlendBody(model)
    camera = front_camera(model)
    rest = Poses.identity(1, model.skeleton.num_bones)
    return body, Standing(body, Parts(body)), camera, rest, observation(model, rest, camera, noise=noise)


def test_upside_down_is_a_finding_and_the_rest_pose_is_not(model):
    body, standing, camera, rest, obs = _rest_seen(model)
    assert standing.findings(body, rest, obs, camera, UP) == ([], [])
    flipped = rest.take(0)
    F = model.skeleton.frames[0]
    flip = np.diag([1.0, -1.0, -1.0])                         # half a turn about world x
    flipped.rotations[0, 0] = matrix_to_quat(F.T @ flip @ F)
    stance, _ = standing.findings(body, flipped, obs, camera, UP)
    assert any("upside down" in f for f in stance)


def test_a_part_in_free_space_is_named(model):
    body, standing, camera, rest, obs = _rest_seen(model)
    moved = rest.take(0)
    b = role_bones(model.skeleton.names)["upper_arm.L"]
    moved.rotations[0, b] = rotvec_to_quat(np.array([0.0, 1.2, 0.0]))     # the left arm swung where nobody is
    stance, found = standing.findings(body, moved, obs, camera, UP)
    assert stance == [] and any(f.startswith("left") and "sees through" in f for f in found), found


def test_a_few_centimetres_off_is_not_seeing_through(model):
    """The whole body moved 3 cm sideways is a small error (no finding); 40 cm, the camera sees past it."""
    body, standing, camera, rest, obs = _rest_seen(model, noise=True)
    for shift, expect in ((0.03, False), (0.4, True)):
        moved = rest.take(0)
        moved.translations[0] = (shift, 0.0, 0.0)
        _, parts = standing.findings(body, moved, obs, camera, UP)
        assert bool(parts) == expect, (shift, parts)
