"""The frames a tracker reads: unregistered captures from files or arrays, cleaned and thinned.

A :class:`CaptureSource` is a lazy, indexable sequence of :class:`.frame_fit.Capture` (one per input
frame, input order): files are read when a frame is asked for, so a long recording is never held in
memory as a whole.  Every frame is cleaned the same way: rows with NaN or infinite coordinates are
dropped (with the triangles that use them), unused vertices are removed, and a mesh with more than
``max_points`` vertices is thinned by vertex clustering (:func:`thin_mesh`, captured vertices kept): the
correspondence search and the trimming cost grow with the capture, the fit's accuracy does not once the
capture is several times denser than the model (docs/track.md "Pipeline").  Coordinates are used as the files hold them
(no axis conversion), metres.
"""
from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..depth.frames import pca_normals, voxel_groups
from ..errors import ArticulaInputError
from ..formats.mesh_files import MESH_EXTENSIONS, read_mesh
from ..formats.point_files import read_point_file
from ..geometry.normals import vertex_normals
from .frame_fit import Capture

POINT_EXTENSIONS = (".npy", ".xyz", ".txt")
CLOUD_NEIGHBOURS = 12       # neighbours of a point-cloud normal estimate


@dataclasses.dataclass
class FrameInfo:
    """What cleaning did to one frame: points read, NaN rows dropped, points kept after thinning."""
    read: int
    dropped_nan: int
    kept: int


def clean(points, triangles=None):
    """``(points, triangles)`` without rows holding NaN/inf, the triangles using them and unused
    vertices (meshes); ``triangles`` None for a point cloud.  Also returns the number of rows dropped."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    good = np.isfinite(points).all(axis=1)
    dropped = int((~good).sum())
    if triangles is None:
        return points[good], None, dropped
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(tris) and (tris.min() < 0 or tris.max() >= len(points)):
        raise ArticulaInputError(f"capture: a triangle uses vertex {int(tris.max())} (or a negative index) but "
                                 f"the capture has {len(points)} points")
    tris = tris[good[tris].all(axis=1)]
    tris = tris[_nondegenerate(tris)]
    used = np.zeros(len(points), dtype=bool)
    used[tris.ravel()] = True
    remap = np.cumsum(used) - 1
    return points[used], remap[tris], dropped


def thin_mesh(points, triangles, max_points: int):
    """Vertex clustering of a triangle mesh to at most about ``max_points`` vertices: the vertices in one
    cubic cell (:func:`..depth.frames.voxel_groups`, cells anchored at the mesh's lowest corner) become
    the one of them nearest their mean, triangles are remapped, collapsed and repeated ones removed.  The
    cell size is found by bisection on the occupied-cell count (metres; 12 halvings).  A captured vertex,
    not the cell's mean: on a curved part the mean lies inside the surface (a 1 cm cell on a finger:
    up to ~1 mm), which biased the fit of noise-free captures (docs/track.md "7 Dec, day")."""
    if len(points) <= max_points:
        return points, triangles
    shifted = points - points.min(axis=0)
    lo, hi = 0.0, float(np.ptp(points, axis=0).max()) or 1.0
    for _ in range(12):
        size = 0.5 * (lo + hi)
        if voxel_groups(shifted, size)[1] > max_points:
            lo = size
        else:
            hi = size
    group, m = voxel_groups(shifted, hi)
    counts = np.bincount(group, None, m)
    mean = np.stack([np.bincount(group, points[:, k], m) for k in range(3)], axis=1) / counts[:, None]
    off = np.linalg.norm(points - mean[group], axis=1)
    order = np.lexsort((off, group))                     # by cell, the nearest to the mean first
    first = np.ones(len(order), bool)
    first[1:] = group[order][1:] != group[order][:-1]
    tris = group[triangles]
    return points[order[first]], tris[np.sort(_keep_first(tris))]


def _nondegenerate(tris):
    """``(F,)`` bool: the triangles of ``tris (F, 3)`` whose three vertices differ."""
    return (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])


def _keep_first(tris):
    """Indices of the non-degenerate triangles of ``tris (F, 3)``, each vertex set once (first kept),
    with the original winding."""
    ok = np.flatnonzero(_nondegenerate(tris))
    _, first = np.unique(np.sort(tris[ok], axis=1), axis=0, return_index=True)
    return ok[first]


def thin_cloud(points, max_points: int, seed: int = 0):
    """A random subset of ``max_points`` points (seeded; input order kept)."""
    if len(points) <= max_points:
        return points
    keep = np.sort(np.random.default_rng(seed).choice(len(points), max_points, replace=False))
    return points[keep]


def cloud_normals(points, centre=None, neighbours: int = CLOUD_NEIGHBOURS):
    """Unit normals ``(N, 3)`` of a point cloud (:func:`..depth.frames.pca_normals`), oriented away from
    ``centre`` (default: the cloud's centroid; a capture seen by cameras would orient towards them, which
    a plain cloud file does not record)."""
    if len(points) < 3:
        return np.zeros_like(points)
    centre = points.mean(axis=0) if centre is None else centre
    return pca_normals(points, neighbours, away_from=centre).astype(np.float64)


def make_capture(points, triangles=None, cameras=None, max_points: int = 0):
    """A cleaned, optionally thinned :class:`Capture` and its :class:`FrameInfo`; normals from the
    triangles (area-weighted) or, for a cloud, from :func:`cloud_normals`."""
    pts, tris, dropped = clean(points, triangles)
    read = len(pts) + dropped
    if max_points and len(pts) > max_points:
        if tris is None:
            pts = thin_cloud(pts, max_points)
        else:
            pts, tris = thin_mesh(pts, tris, max_points)
    if tris is not None and len(tris) == 0:
        tris = None
    normals = cloud_normals(pts) if tris is None else vertex_normals(pts, tris)
    return Capture(pts, normals, tris, cameras), FrameInfo(read, dropped, len(pts))


class CaptureSource:
    """Frames to track, read on demand.  ``len(source)``, ``source[i]`` -> :class:`Capture` (cleaned and
    thinned to ``max_points``; 0 keeps all), ``source.info(i)`` -> :class:`FrameInfo` of the last read,
    ``source.names`` one label per frame (file names).  ``cameras``: None, or per frame a list of
    ``(cam_to_world, Intrinsics)`` used for visibility."""

    def __init__(self, names, reader, cameras=None, max_points: int = 0):
        self.names, self._reader, self.max_points = list(names), reader, int(max_points)
        self.cameras = cameras
        self._info = {}

    def __len__(self):
        return len(self.names)

    def __getitem__(self, i) -> Capture:
        i = int(i)
        if not 0 <= i < len(self):
            raise IndexError(i)
        points, triangles = self._reader(i)
        cams = None if self.cameras is None else self.cameras[i]
        capture, self._info[i] = make_capture(points, triangles, cams, self.max_points)
        return capture

    def info(self, i) -> FrameInfo:
        return self._info.get(int(i))

    def with_max_points(self, max_points: int) -> "CaptureSource":
        """The same frames thinned to ``max_points``."""
        return CaptureSource(self.names, self._reader, self.cameras, max_points)

    @classmethod
    def from_arrays(cls, points, triangles=None, cameras=None, max_points: int = 0, names=None):
        """Frames from lists of ``points (N_i, 3)`` and ``triangles (G_i, 3)`` (None: point clouds)."""
        points = list(points)
        triangles = [None] * len(points) if triangles is None else list(triangles)
        if len(triangles) != len(points):
            raise ArticulaInputError(f"captures: {len(points)} point arrays but {len(triangles)} triangle arrays")
        names = names or [f"frame {i + 1}" for i in range(len(points))]
        return cls(names, lambda i: (points[i], triangles[i]), cameras, max_points)

    @classmethod
    def from_files(cls, paths, cameras=None, max_points: int = 0):
        """Frames from mesh files (OBJ, PLY, STL, OFF: triangulated) or point files (.npy, .xyz, .txt);
        a PLY without faces is read as a point cloud.  Files are checked for existence up front."""
        paths = [os.fspath(p) for p in paths]
        if not paths:
            raise ArticulaInputError("captures: no files given")
        missing = [p for p in paths if not os.path.isfile(p)]
        if missing:
            raise ArticulaInputError(f"captures: {len(missing)} file(s) not found, first {missing[0]}")
        bad = [p for p in paths if os.path.splitext(p)[1].lower() not in MESH_EXTENSIONS + POINT_EXTENSIONS]
        if bad:
            raise ArticulaInputError(f"{bad[0]}: not a mesh ({', '.join(MESH_EXTENSIONS)}) or point file "
                                     f"({', '.join(POINT_EXTENSIONS)})")
        return cls([os.path.basename(p) for p in paths], lambda i: read_capture_file(paths[i]), cameras,
                   max_points)


def read_capture_file(path):
    """``(points (N, 3), triangles (G, 3) or None)`` of one capture file, coordinates as written."""
    ext = os.path.splitext(path)[1].lower()
    if ext in POINT_EXTENSIONS:
        return read_point_file(path)[0].astype(np.float64), None
    mesh = read_mesh(path)
    tris = mesh.triangles() if len(mesh.face_sizes) else None
    return mesh.vertices.astype(np.float64), tris
