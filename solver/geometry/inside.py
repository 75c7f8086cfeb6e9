"""Inside/outside of triangle meshes by the generalized winding number, and the distance of points outside
a mesh to its surface.

* :func:`winding_numbers` — w(p) = Σ_f Ω_f(p) / 4π, the signed solid angle Ω_f of every triangle seen from
  p over the full sphere (Jacobson, Kavan and Sorkine-Hornung, "Robust Inside-Outside Segmentation using
  Generalized Winding Numbers", SIGGRAPH 2013).  Ω_f by the formula of Van Oosterom and Strackee ("The
  Solid Angle of a Plane Triangle", IEEE Trans. Biomed. Eng. 1983): with a, b, c the corners relative to p,
  ``tan(Ω/2) = det[a b c] / (|a||b||c| + (a·b)|c| + (b·c)|a| + (c·a)|b|)``.  For a closed, consistently
  oriented mesh w is 1 inside (−1 if the faces point inwards) and 0 outside; for a mesh with holes or
  cracks it varies smoothly and stays near those values away from the gaps.
* :func:`distance_outside` — 0 for points inside (|w| > 0.5), else the exact distance to the nearest
  triangle (:func:`solver.geometry.surface_distance.distance_to_surface`).

Work is done in chunks of at most ``CHUNK_PAIRS`` point/triangle pairs, so the temporary memory stays
bounded (about 170 bytes per pair, 45 MB) for any number of points and triangles.  Units: those of the input (metres in
Articula); winding numbers are unitless.
"""
import numpy as np

from .surface_distance import distance_to_surface

CHUNK_PAIRS = 1 << 18   # point/triangle pairs evaluated at once
INSIDE = 0.5            # |winding number| above this: inside


def _as_mesh(points, vertices, faces):
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError(f"faces refer to vertices outside 0..{len(vertices) - 1}")
    return points, vertices, faces


def _solid_angles(p, a, b, c):
    """Summed signed solid angle ``(n,)`` of the triangles ``a, b, c (f, 3)`` seen from each of ``p (n, 3)``."""
    A, B, C = a[None] - p[:, None], b[None] - p[:, None], c[None] - p[:, None]     # (n, f, 3)
    la, lb, lc = (np.sqrt(np.einsum("nfi,nfi->nf", x, x)) for x in (A, B, C))
    det = np.einsum("nfi,nfi->nf", A, np.cross(B, C))
    den = (la * lb * lc + np.einsum("nfi,nfi->nf", A, B) * lc + np.einsum("nfi,nfi->nf", B, C) * la
           + np.einsum("nfi,nfi->nf", C, A) * lb)
    return 2.0 * np.arctan2(det, den).sum(axis=1)


def winding_numbers(points, vertices, faces):
    """Generalized winding number ``(P,)`` of every point ``(P, 3)`` with respect to the triangle mesh
    ``vertices (V, 3)``, ``faces (F, 3)`` (Jacobson et al. 2013; module docstring).  1 inside and 0 outside
    a closed mesh whose faces are counter-clockwise seen from outside; a point on the surface gets about
    0.5."""
    points, vertices, faces = _as_mesh(points, vertices, faces)
    out = np.zeros(len(points))
    if not len(points) or not len(faces):
        return out
    tri = np.take(vertices, faces, axis=0)                                          # (F, 3, 3)
    per_points = max(1, CHUNK_PAIRS // len(faces))
    per_faces = max(1, min(len(faces), CHUNK_PAIRS))
    for i in range(0, len(points), per_points):
        p = points[i:i + per_points]
        for j in range(0, len(faces), per_faces):
            t = tri[j:j + per_faces]
            out[i:i + per_points] += _solid_angles(p, t[:, 0], t[:, 1], t[:, 2])
    return out / (4.0 * np.pi)


def distance_outside(points, vertices, faces):
    """``(P,)``: 0 for points ``(P, 3)`` inside the mesh ``vertices (V, 3)``, ``faces (F, 3)`` (|winding
    number| > 0.5, either face orientation), else the Euclidean distance to the nearest point of its
    surface, in the units of the input."""
    points, vertices, faces = _as_mesh(points, vertices, faces)
    out = np.zeros(len(points))
    if not len(points):
        return out
    outside = np.abs(winding_numbers(points, vertices, faces)) <= INSIDE
    if outside.any():
        out[outside] = distance_to_surface(points[outside], vertices, faces)
    return out
