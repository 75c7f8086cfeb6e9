"""Which model points the camera sees (depth-camera tracking dissertation ch. 5, relaxed visibility, and
ch. 6, Algorithm 3): inside the view, facing the camera, and not behind the model's own rendered depth by
more than a tolerance.  The model depth is rendered by splatting each front-facing point over the 3x3
cells of half a point spacing around it, so the splats close the gaps between points."""
from __future__ import annotations

import numpy as np

NEAR_M = 0.1
POINT_SPACING_M = 0.05   # about the spacing of ~1000 points on a body
SPLAT = ((0, 0), (1, 0), (0, 1), (1, 1), (-1, 0), (0, -1), (-1, -1), (1, -1), (-1, 1))


def in_view(uv: np.ndarray, z: np.ndarray, intr) -> np.ndarray:
    """(N,) True for points in front of the camera and inside the image."""
    with np.errstate(invalid="ignore"):
        return (z > NEAR_M) & (uv[:, 0] >= 0) & (uv[:, 0] < intr.width) & (uv[:, 1] >= 0) & (uv[:, 1] < intr.height)


def facing(points: np.ndarray, normals: np.ndarray, centre: np.ndarray, slack: float = 0.0) -> np.ndarray:
    """(N,) True where the normal points towards the camera centre (cosine above ``-slack``)."""
    ray = points - centre
    return (normals * ray).sum(axis=1) < slack * np.linalg.norm(ray, axis=1)


def visible(points, normals, camera, tolerance: float, spacing: float = POINT_SPACING_M) -> np.ndarray:
    """(N,) bool: the points the camera sees (see the module docstring)."""
    uv, z = camera.project(points)
    ok = in_view(uv, z, camera.intr) & facing(points, normals, camera.centre)
    if not ok.any():
        return ok
    zs = z[ok]
    cell = max(1.0, 0.5 * camera.intr.fx * spacing / float(np.median(zs)))
    W = int(np.ceil(camera.intr.width / cell)) + 2
    H = int(np.ceil(camera.intr.height / cell)) + 2
    cu = (uv[ok, 0] / cell).astype(np.int64)
    cv = (uv[ok, 1] / cell).astype(np.int64)
    flat = cv * W + cu
    buf = np.full(W * H, np.inf)
    for du, dv in SPLAT:          # each point covers the 2x2 cells (one point spacing) around it
        np.minimum.at(buf, flat + dv * W + du, zs)
    out = np.zeros(len(points), bool)
    out[np.flatnonzero(ok)] = zs <= buf[flat] + tolerance
    return out
