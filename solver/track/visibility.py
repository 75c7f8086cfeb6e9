"""Which model vertices the capture's cameras can see: back-face test plus a depth-buffer render.

The visibility constraint of the model-adaptive mocap dissertation §4.1.2 ("any template model vertex
which is occluded with respect to all of the sensing devices is discarded"), with the depth-buffer
render its §4.3 recommends instead of testing every triangle, and the back-face test of the
depth-camera tracking literature it builds on.  A vertex is visible from a camera when it projects
into the image in front of the camera, its normal faces the camera centre, and its depth is within a
tolerance of the model's own z-buffer at its pixel; it takes part when some camera sees it.

Cameras are ``(cam_to_world (4, 4), Intrinsics)`` in the conventions of ``solver.depth.camera``
(OpenCV axes: +Z forward; metres).  The z-buffer can be rendered at a reduced resolution
(``scale``): occlusion by a body needs only a few pixels per limb.
"""
from __future__ import annotations

import numpy as np

from ..depth import camera as cam

CHUNK = 500_000     # candidate pixels rasterised at once (bounds memory to some tens of MB)
NEAR = 1e-3         # triangles with a vertex closer than this (m) to the camera plane are not drawn
MIN_COS = 0.2       # grazing vertices get the depth tolerance of a 78 deg slant, no more


def depth_buffer(vertices_cam, triangles, intr):
    """Z-buffer ``(H, W)`` of a mesh given in the camera frame (``vertices_cam (V, 3)`` m, ``triangles
    (F, 3)``): the smallest depth Z of the surface at each pixel centre, ``inf`` where nothing is drawn.

    Every triangle is tested at the pixel centres of its bounding box, all triangles at once (in
    chunks); inside by screen-space barycentric coordinates with shared edges included; depth by
    interpolating 1/Z, which is affine on the screen, so it is the exact depth of the triangle along
    the pixel's ray.  Triangles reaching behind :data:`NEAR` are skipped (no clipping)."""
    height, width = intr.height, intr.width
    uv, z = cam.project(np.asarray(vertices_cam, dtype=np.float64), intr)
    tris, boxes = _pixel_boxes(uv, z, np.asarray(triangles, dtype=np.int64).reshape(-1, 3), width, height)
    zbuf = np.full(height * width, np.inf)
    ends = np.cumsum(boxes[:, 4])
    start = 0
    while start < len(tris):
        stop = max(start + 1, int(np.searchsorted(ends, (ends[start - 1] if start else 0) + CHUNK, "right")))
        pixels, depths = _rasterise(uv, 1.0 / z, tris[start:stop], boxes[start:stop], width)
        np.minimum.at(zbuf, pixels, depths)
        start = stop
    return zbuf.reshape(height, width)


def _pixel_boxes(uv, z, triangles, width, height):
    """Drawable triangles ``(T, 3)`` and their pixel-centre boxes ``(T, 5)``: u0, v0, box width, box
    height, pixel count (triangles behind NEAR or wholly outside the image dropped)."""
    front = np.all(z[triangles] > NEAR, axis=1)
    tris = triangles[front]
    tu, tv = uv[tris, 0], uv[tris, 1]
    u0 = np.maximum(np.ceil(tu.min(1)), 0)
    v0 = np.maximum(np.ceil(tv.min(1)), 0)
    bw = np.minimum(np.floor(tu.max(1)), width - 1) - u0 + 1
    bh = np.minimum(np.floor(tv.max(1)), height - 1) - v0 + 1
    keep = (bw > 0) & (bh > 0)
    boxes = np.stack([u0, v0, bw, bh, bw * bh], axis=1)[keep].astype(np.int64)
    return tris[keep], boxes


def _rasterise(uv, inv_z, tris, boxes, width):
    """Pixel ids and depths of the pixel centres inside ``tris`` (within their ``boxes``)."""
    counts = boxes[:, 4]
    owner = np.repeat(np.arange(len(tris)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    pu = boxes[owner, 0] + local % boxes[owner, 2]
    pv = boxes[owner, 1] + local // boxes[owner, 2]
    a, b, c = (uv[tris[:, i]] for i in range(3))
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    ok = np.abs(area) > 1e-12
    inv_area = np.where(ok, 1.0 / np.where(ok, area, 1.0), 0.0)
    # barycentric weights of the pixel centre: signed areas of the sub-triangles opposite a and b
    wa = ((b[owner, 0] - pu) * (c[owner, 1] - pv) - (b[owner, 1] - pv) * (c[owner, 0] - pu)) * inv_area[owner]
    wb = ((c[owner, 0] - pu) * (a[owner, 1] - pv) - (c[owner, 1] - pv) * (a[owner, 0] - pu)) * inv_area[owner]
    wc = 1.0 - wa - wb
    inside = (wa >= -1e-9) & (wb >= -1e-9) & (wc >= -1e-9) & ok[owner]
    own = owner[inside]
    iz = inv_z[tris[own]]
    inv_depth = wa[inside] * iz[:, 0] + wb[inside] * iz[:, 1] + wc[inside] * iz[:, 2]
    return pv[inside] * width + pu[inside], 1.0 / inv_depth


def seen_by_camera(vertices, normals, triangles, cam_to_world, intr, tolerance_m=0.005, tolerance_px=2.0):
    """``(V,)`` bool: the vertices one camera sees (world ``vertices (V, 3)`` m, unit ``normals (V, 3)``).

    Seen = in front of the camera and inside its image, normal towards the camera centre
    (cos = n . (eye - v) / |eye - v| > 0), and depth at most ``tolerance_m + tolerance_px * Z / (f cos)``
    behind the z-buffer at the vertex's pixel: the second part is the depth change across
    ``tolerance_px`` pixel footprints of a surface slanted by the angle (cos floored at :data:`MIN_COS`),
    which the pixel centre's depth can differ by from the vertex's own."""
    v = np.asarray(vertices, dtype=np.float64)
    view = cam_to_world[:3, 3] - v
    cos = np.einsum("ij,ij->i", np.asarray(normals, dtype=np.float64), view) / np.linalg.norm(view, axis=1)
    facing = cos > 0
    vc = cam.world_to_camera(v, cam_to_world)
    uv, z = cam.project(vc, intr)
    with np.errstate(invalid="ignore"):
        col, row = np.rint(uv[:, 0]), np.rint(uv[:, 1])
        inside = (z > NEAR) & (col >= 0) & (col < intr.width) & (row >= 0) & (row < intr.height)
    out = facing & inside
    if not out.any():
        return out
    zbuf = depth_buffer(vc, triangles, intr).ravel()
    idx = np.flatnonzero(out)
    pix = row[idx].astype(np.int64) * intr.width + col[idx].astype(np.int64)
    slack = tolerance_m + tolerance_px * z[idx] / min(intr.fx, intr.fy) / np.maximum(cos[idx], MIN_COS)
    out[idx] = z[idx] <= zbuf[pix] + slack
    return out


def visible_vertices(vertices, normals, triangles, cameras, scale=1.0, tolerance_m=0.005, tolerance_px=2.0):
    """``(V,)`` bool: vertices seen by at least one of ``cameras`` (list of ``(cam_to_world, Intrinsics)``);
    all True when ``cameras`` is None or empty.  ``scale`` < 1 renders the z-buffers at that fraction
    of each camera's resolution (``Intrinsics.with_resolution``)."""
    n = len(vertices)
    if not cameras:
        return np.ones(n, dtype=bool)
    seen = np.zeros(n, dtype=bool)
    for cam_to_world, intr in cameras:
        if scale != 1.0:
            intr = intr.with_resolution(max(1, round(intr.width * scale)), max(1, round(intr.height * scale)))
        seen |= seen_by_camera(vertices, normals, triangles, np.asarray(cam_to_world, dtype=np.float64), intr,
                               tolerance_m, tolerance_px)
    return seen
