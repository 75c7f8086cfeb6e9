"""A numpy z-buffer triangle rasteriser for synthetic depth images.

Renders a triangle mesh given in the camera frame (``solver.depth.camera`` conventions: +X right, +Y down,
+Z forward, metres) into a pinhole depth image:

* every triangle is tested against the pixel centres of its bounding box, all triangles at once
  (candidates are expanded into flat arrays, in chunks to bound memory);
* inside test by screen-space barycentric coordinates, inclusive of edges, so meshes are watertight
  in the image (shared-edge pixels are resolved by the depth test);
* depth is interpolated as 1/Z, which is affine in screen space for a planar triangle under
  perspective, so the rendered value is the exact Z where the pixel ray meets the triangle;
* the nearest candidate per pixel wins (``np.minimum.at``); ties go to the lower triangle id.

Triangles with any vertex closer than ``near`` are dropped (no clipping), which is harmless for
scenes kept in front of the camera.  Output depth 0 means "no surface"; ``tri_id`` -1 likewise.
"""
from __future__ import annotations

import numpy as np

from ..solver.depth.camera import Intrinsics, project
from ..solver.errors import ArticulaInputError

CHUNK = 400_000  # candidate pixels processed at once (bounds memory to a few tens of MB)


def render_depth(vertices_cam: np.ndarray, faces: np.ndarray, intr: Intrinsics, near: float = 0.05):
    """Rasterise a mesh.

    ``vertices_cam``: (V, 3) camera-frame positions (m); ``faces``: (F, 3) vertex ids.
    Returns ``depth`` (H, W) float64 Z in metres (0 = nothing) and ``tri_id`` (H, W) int32 face index
    seen in each pixel (-1 = nothing).
    """
    verts = np.asarray(vertices_cam, dtype=float)
    faces = np.asarray(faces)
    if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ArticulaInputError(f"render_depth: expected (V,3) vertices and (F,3) faces, "
                                 f"got {verts.shape} and {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        raise ArticulaInputError("render_depth: face indices out of range")
    height, width = intr.shape
    uv, z = project(verts, intr)
    tri, box = _candidate_triangles(uv, z, faces, intr, near)
    zbuf = np.full(height * width, np.inf)
    hits = []
    for sel in _chunks(box[:, 4], CHUNK):
        pix, t, zc = _rasterise(uv, z, faces, tri[sel], box[sel], width)
        np.minimum.at(zbuf, pix, zc)
        hits.append((pix, t, zc))
    ids = np.full(height * width, np.iinfo(np.int32).max, np.int64)
    for pix, t, zc in hits:
        win = zc == zbuf[pix]
        np.minimum.at(ids, pix[win], t[win])
    covered = np.isfinite(zbuf)
    depth = np.where(covered, zbuf, 0.0).reshape(height, width)
    tri_id = np.where(covered, ids, -1).astype(np.int32).reshape(height, width)
    return depth, tri_id


def _candidate_triangles(uv, z, faces, intr, near):
    """Triangles in front of the camera overlapping the image, with their pixel bounding boxes
    (u0, v0, bw, bh, n_pixels) as an (T, 5) int64 array."""
    zf = z[faces]
    keep = np.all(zf > near, axis=1)
    tri = np.flatnonzero(keep)
    fu, fv = uv[faces[tri], 0], uv[faces[tri], 1]
    u0 = np.maximum(np.ceil(fu.min(1)), 0)
    u1 = np.minimum(np.floor(fu.max(1)), intr.width - 1)
    v0 = np.maximum(np.ceil(fv.min(1)), 0)
    v1 = np.minimum(np.floor(fv.max(1)), intr.height - 1)
    bw, bh = u1 - u0 + 1, v1 - v0 + 1
    ok = (bw > 0) & (bh > 0)
    box = np.stack([u0, v0, bw, bh, bw * bh], axis=1)[ok].astype(np.int64)
    return tri[ok], box


def _chunks(counts, limit):
    """Split triangle indices into consecutive slices holding about ``limit`` candidates each."""
    ends = np.cumsum(counts)
    cuts = np.searchsorted(ends, np.arange(limit, ends[-1] if len(ends) else 0, limit), side="right")
    bounds = np.unique(np.r_[0, cuts, len(counts)])
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def _rasterise(uv, z, faces, tri, box, width):
    """Candidate pixels of the triangles ``tri`` inside their boxes -> (pixel, triangle, depth)."""
    counts = box[:, 4]
    owner = np.repeat(np.arange(len(tri)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    bw = box[owner, 2]
    pu = box[owner, 0] + local % bw
    pv = box[owner, 1] + local // bw
    f = faces[tri]
    a, b, c = uv[f[:, 0]], uv[f[:, 1]], uv[f[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    good = np.abs(area) > 1e-12
    inv_area = np.where(good, 1.0 / np.where(good, area, 1.0), 0.0)[owner]
    a, b, c = a[owner], b[owner], c[owner]
    # barycentric weights of the pixel centre (pu, pv) from signed sub-triangle areas
    l0 = ((b[:, 0] - pu) * (c[:, 1] - pv) - (b[:, 1] - pv) * (c[:, 0] - pu)) * inv_area
    l1 = ((c[:, 0] - pu) * (a[:, 1] - pv) - (c[:, 1] - pv) * (a[:, 0] - pu)) * inv_area
    l2 = 1.0 - l0 - l1
    eps = -1e-9
    inside = (l0 >= eps) & (l1 >= eps) & (l2 >= eps) & good[owner]
    iz = 1.0 / z[f]  # (T, 3)
    own = owner[inside]
    inv_depth = l0[inside] * iz[own, 0] + l1[inside] * iz[own, 1] + l2[inside] * iz[own, 2]
    pix = pv[inside] * width + pu[inside]
    return pix, tri[own], 1.0 / inv_depth


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) unit normals (right-handed winding; zero for degenerate faces)."""
    v = np.asarray(vertices, dtype=float)
    n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def incidence_cosine(vertices_cam, faces, tri_id, intr: Intrinsics) -> np.ndarray:
    """(H, W) |cos| of the angle between the seen face's normal and the pixel's viewing ray
    (1 = facing the camera, 0 = grazing or no surface)."""
    seen = np.flatnonzero(tri_id.ravel() >= 0)
    rows, cols = np.divmod(seen, intr.width)
    rays = np.stack([(cols - intr.cx) / intr.fx, (rows - intr.cy) / intr.fy, np.ones(len(seen))], axis=1)
    normals = face_normals(vertices_cam, np.asarray(faces))[tri_id.ravel()[seen]]
    cos = np.zeros(tri_id.size)
    cos[seen] = np.abs(np.einsum("ij,ij->i", normals, rays)) / np.linalg.norm(rays, axis=1)
    return cos.reshape(tri_id.shape)


def visible_vertices(tri_id: np.ndarray, faces: np.ndarray, n_faces: int | None = None) -> np.ndarray:
    """Sorted unique ids of the vertices of faces seen in at least one pixel.

    ``n_faces``: only faces with index < n_faces count (the subject when scenery faces are
    appended after it)."""
    seen = np.unique(tri_id[tri_id >= 0])
    if n_faces is not None:
        seen = seen[seen < n_faces]
    return np.unique(np.asarray(faces)[seen])
