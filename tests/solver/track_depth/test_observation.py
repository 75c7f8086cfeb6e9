"""One depth frame as the tracker sees it: the person's connected component, silhouette normals, the
floor band, free space, and points rendered back into a depth image; visibility of model points."""
import numpy as np
import pytest

from articula.solver.depth import frames as dp
from articula.solver.track_depth.observation import (ViewCamera, connected_person, depth_image, observe)
from articula.solver.track_depth.visibility import visible
from articula.solver.depth import camera as cam

from .conftest import front_camera, mild_poses, observation


def _plane_grid(depth, intr):
    return dp.backproject_grid(depth, dp.pixel_rays(intr))


def test_largest_component_with_parts_within_reach_and_not_far_objects():
    intr = cam.preset("kinect_v1", (80, 60))
    z = np.full((60, 80), np.nan, np.float32)
    z[10:50, 30:45] = 2.5                   # the body
    z[12:20, 45:52] = 2.44                  # a forearm towards the camera: a depth jump at the body's edge
    z[40:55, 60:75] = 1.2                   # a chair far in front, not touching in 3D
    z[30:34, 45:60] = 2.5                   # ... but touching the body in the image via a strip at its depth
    z[30:34, 59:61] = 1.2
    keep = np.isfinite(z)
    person, others = connected_person(keep, _plane_grid(z, intr), z, noise=0.0)
    assert person[15, 48] and person[20, 35]            # forearm rejoined across the jump
    assert not person[45, 70]                           # chair excluded
    assert others == []                                 # ... and too small to be a second person


def _two_people():
    intr = cam.preset("kinect_v1", (80, 60))
    z = np.full((60, 80), np.nan, np.float32)
    z[5:55, 34:46] = 2.5                    # one in the middle
    z[8:52, 62:72] = 3.5                    # another to the right, farther
    z[10:50, 4:16] = 2.0                    # a third to the left, nearest
    return z, _plane_grid(z, intr)


@pytest.mark.parametrize("choose, column", [("centre", 40), ("nearest", 10), ("right", 66), ("left", 10),
                                            ("largest", 40)])
def test_person_chosen_and_the_others_named(choose, column):
    z, grid = _two_people()
    person, others = connected_person(np.isfinite(z), grid, z, noise=0.0, choose=choose)
    assert person[30, column] and person.sum() == np.isfinite(z[:, column - 6:column + 7]).sum()
    assert len(others) == 2 and all(px > 300 for px, _ in others)


def test_followed_person_is_kept_over_the_rule():
    z, grid = _two_people()
    follow = grid[30, 66]                   # last frame's person stood on the right
    person, others = connected_person(np.isfinite(z), grid, z, noise=0.0, choose="centre", follow=follow)
    assert person[30, 66] and not person[30, 40] and len(others) == 2


def test_nobody_gives_an_empty_observation(model):
    camera = front_camera(model)
    z = np.full((240, 320), np.nan, np.float32)
    obs = observe(z, dp.pixel_rays(camera.intr), camera, dp.DepthOptions(remove_floor=False))
    assert obs.empty and obs.person_pixels == 0


def test_silhouette_normals_point_outwards(model):
    camera = front_camera(model)
    obs = observation(model, mild_poses(model, seed=0, angle=0.0), camera)
    H, W = obs.mask.shape

    def inside(step):
        p = np.round(obs.edge_pixels + step * obs.edge_normals).astype(int)
        ok = (p[:, 0] >= 0) & (p[:, 0] < W) & (p[:, 1] >= 0) & (p[:, 1] < H)
        return np.where(ok, obs.mask[np.clip(p[:, 1], 0, H - 1), np.clip(p[:, 0], 0, W - 1)], False)
    assert len(obs.edge_pixels) > 50
    assert inside(-2.0).mean() > 0.8 and inside(2.0).mean() < 0.2


def test_points_rendered_back_land_on_their_pixels(model):
    camera = front_camera(model)
    obs = observation(model, mild_poses(model, seed=1), camera)
    z = depth_image(camera.to_camera(obs.points), camera.intr)
    u, v = obs.pixels[:, 0].astype(int), obs.pixels[:, 1].astype(int)
    assert np.allclose(z[v, u], camera.to_camera(obs.points)[:, 2], atol=1e-5)


def test_free_space(model):
    camera = front_camera(model)
    obs = observation(model, mild_poses(model, seed=0, angle=0.0), camera)
    on_body = obs.points[:50]
    beside = on_body + np.array([1.0, 0.0, 0.0])          # a metre to the side: nothing seen there
    assert not obs.in_free_space(on_body, camera).any() and obs.in_free_space(beside, camera).all()


def test_visibility_excludes_back_and_occluded_points(model):
    from articula.solver.tracking.blend_body import BlendBody
    camera = front_camera(model)
    body = BlendBody(model, count=1000)
    posed = body.pose(mild_poses(model, seed=0, angle=0.0))
    vis = visible(posed.points, posed.normals, camera, 0.03)
    toward = (posed.normals * (camera.centre - posed.points)).sum(axis=1) > 0
    assert not vis[~toward].any() and 0.25 < vis.mean() < 0.6
    # points of the back turned to face the camera are still hidden behind the front (the splatted
    # model depth may leave a few gaps between its points)
    back = np.flatnonzero(~toward & (np.abs(posed.points[:, 0]) < 0.12) & (posed.points[:, 2] > 0.9)
                          & (posed.points[:, 2] < 1.4))
    n = posed.normals.copy()
    n[back] = -n[back]
    assert len(back) > 10 and visible(posed.points, n, camera, 0.03)[back].mean() < 0.2


def test_box_counts_match_brute_force():
    from articula.solver.track_depth.observation import _box_count, _summed_area
    rng = np.random.default_rng(4)
    img = rng.random((23, 31)) < 0.2
    u, v, r = rng.integers(0, 31, 40), rng.integers(0, 23, 40), rng.integers(0, 6, 40)
    want = [img[max(b - k, 0):b + k + 1, max(a - k, 0):a + k + 1].sum() for a, b, k in zip(u, v, r)]
    assert np.array_equal(_box_count(_summed_area(img), u, v, r), want)
