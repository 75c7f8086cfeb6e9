"""Exact synthetic depth images by analytic ray casting (the independent reference for the depth
import tests and ``./run bench import_depth``): a floor plane (world z = 0) seen by a tilted camera,
optionally an axis-aligned box standing on it and a back wall; plus a sphere.  World Z up; camera frame x right, y down, z forward."""
import numpy as np

from ..solver.depth import camera


def rays_world(intr, cam_to_world):
    u, v = camera.pixel_grid(intr)
    r = np.stack(((u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)), axis=-1)
    return r @ cam_to_world[:3, :3].T  # (H, W, 3) world direction whose sensor z component is 1


def ray_box(eye, d, lo, hi):
    """Parameter t of the first hit of eye + t d with the box [lo, hi] (inf where missed)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (np.asarray(lo) - eye) / d
        t2 = (np.asarray(hi) - eye) / d
    tmin = np.nanmax(np.minimum(t1, t2), axis=-1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=-1)
    hit = (tmax >= np.maximum(tmin, 0)) & (tmin > 0)
    return np.where(hit, tmin, np.inf)


def floor_box_scene(intr, eye=(0.0, 0.0, 1.2), target=(0.0, 3.0, 0.5), box=((-0.25, 2.2, 0.0), (0.25, 2.7, 0.8)),
                    wall_y=None):
    """Depth (H, W) in metres (0 = nothing), the camera's cam_to_world, and a label image
    (0 none, 1 floor, 2 box, 3 wall)."""
    c2w = camera.look_at(eye, target)
    eye = np.asarray(eye, float)
    d = rays_world(intr, c2w)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[..., 2] < 0, -eye[2] / d[..., 2], np.inf)
        t_wall = np.full(d.shape[:2], np.inf) if wall_y is None else \
            np.where(d[..., 1] > 0, (wall_y - eye[1]) / d[..., 1], np.inf)
    t_box = np.full(d.shape[:2], np.inf) if box is None else ray_box(eye, d, box[0], box[1])
    ts = np.stack((t_floor, t_box, t_wall))
    label = np.argmin(ts, axis=0) + 1
    t = ts.min(axis=0)
    label[~np.isfinite(t)] = 0
    return np.where(np.isfinite(t), t, 0.0), c2w, label


def sphere_depth(intr, centre=(0.1, -0.05, 1.5), radius=0.3):
    """Depth of a sphere given in the camera frame (0 = missed)."""
    u, v = camera.pixel_grid(intr)
    r = np.stack(((u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)), axis=-1)
    c = np.asarray(centre, float)
    a = (r * r).sum(-1)
    b = -2 * (r @ c)
    cc = c @ c - radius ** 2
    disc = b * b - 4 * a * cc
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / (2 * a)
    return np.where(disc > 0, t, 0.0)
